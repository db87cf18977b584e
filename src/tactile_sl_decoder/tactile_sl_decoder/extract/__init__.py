"""Stage 1, image -> glyphs: find the glyphs of one grey image and sample their patches."""
