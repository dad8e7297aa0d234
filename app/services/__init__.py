"""What the routes call: uploads parsed by the engine, try-on requests checked and resolved."""
