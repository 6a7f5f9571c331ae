"""Real captures: photo files, EXIF, undistortion, COLMAP cameras, scene frame, sun, probes."""
