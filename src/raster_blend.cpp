// raster_blend: being written (issue 6).
