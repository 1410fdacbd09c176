"""Reading and writing of point clouds, rasters and vectors; shared by all plugins."""
