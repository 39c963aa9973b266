"""``benchlab run fov``: field of view, direction of view, entrance pupil and image-height
mapping of the forward view from a dot-grid chart at several stage distances (issue 41)."""
