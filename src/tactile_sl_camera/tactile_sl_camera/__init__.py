"""Image sources for the tactile-sl sensor: stereo cameras through OpenCV and bag replay."""
