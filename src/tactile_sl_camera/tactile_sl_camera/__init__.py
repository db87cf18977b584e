"""Image sources for the tactile-sl sensor: stereo capture, simulator, bag replay."""
