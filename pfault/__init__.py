"""pfault: parallel simulation of ground rupture caused by groundwater withdrawal."""

__version__ = "0.1.0"
