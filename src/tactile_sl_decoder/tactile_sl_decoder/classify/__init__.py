"""Stage 2, glyphs -> labels: the patch classifier (a small CNN) and its weights format."""
