"""The inspection cell: robot and cell model files, the plant helpers, geometry, faces, clearance."""
