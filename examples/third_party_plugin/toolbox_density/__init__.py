"""Example third-party plugin for lidar-toolbox: point density rasters."""
