"""Physically grounded simulator of the tactile sensor: optics, pad mechanics, ray casting."""
from .artwork import Artwork, ArtworkError, default_artwork_path, load_artwork
from .contact import Contact, FieldGrid, PadParams
from .optics import Camera, RigParams, SimulatedCameraPair
from .render import GroundTruth, Nuisances, Renderer, StereoFrame

__all__ = ["Artwork", "ArtworkError", "Camera", "Contact", "FieldGrid", "GroundTruth",
           "Nuisances", "PadParams", "Renderer", "RigParams", "SimulatedCameraPair",
           "StereoFrame", "default_artwork_path", "load_artwork"]
