"""tryon engine: bodies, patterns, cloth, image-space collision, scenes. Imports nothing from app/."""

__version__ = "0.1.0"
