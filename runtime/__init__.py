"""Live side of facepuppet: tables, frames, sources, frame loop, renderer."""
