"""tactile-sl pipeline: pattern encoder, glyph extraction, classification, decoding, 3-D."""
