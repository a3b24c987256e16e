"""colourhs: Colour Helmholtz Stereopsis, from raw captures to evaluated meshes."""

__version__ = "0.1.0"
