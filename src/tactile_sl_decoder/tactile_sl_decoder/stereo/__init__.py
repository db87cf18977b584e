"""Stage 4, cells -> points: stereo pairing by cell, triangulation and outlier removal."""
