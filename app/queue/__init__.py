"""The job queue: the supervisor (in the API process) starts worker processes that take queued
try-ons from the database and write their results (SQLite by default)."""
