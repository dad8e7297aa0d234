"""Image-space collision: body maps rendered with OpenGL (maps.py, gl.py) and their queries (query.py)."""
