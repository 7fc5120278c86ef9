"""A 16x12 scene of an area light in a box of isotropic medium, for tests that render
or compare it in a fraction of a second (a scene file's text; tests add sections)."""

TINY = """
[camera]
position   = [0.0, 0.0, -4.0]
look_at    = [0.0, 0.0, 0.0]
up         = [0.0, 1.0, 0.0]
fov_y      = 40.0
resolution = [16, 12]

[medium]
bounds_min = [-1.0, -1.0, -1.0]
bounds_max = [ 1.0,  1.0,  1.0]
sigma_s = 0.8
sigma_a = 0.2
phase   = { type = "isotropic" }

[[lights]]
type = "area"
corner   = [-0.3, 0.95, -0.3]
edge_u   = [0.6, 0.0, 0.0]
edge_v   = [0.0, 0.0, 0.6]
radiance = [3.0, 3.0, 3.0]
"""
