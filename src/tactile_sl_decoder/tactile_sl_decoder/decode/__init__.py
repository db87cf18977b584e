"""Stage 3, labels -> cells: the glyph lattice and the codeword decoder (pattern cells)."""
