"""psurf UI: PyVista views of every stage (the only package that imports pyvista/vtk)."""
