"""Reading and writing rasters, vectors, tables and figures in the project's conventions."""
