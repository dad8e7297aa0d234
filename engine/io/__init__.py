"""Outputs: PNG pictures of maps and bodies, meshes, recordings."""
