"""wott-hub: a gateway for fleets of tactile sensors."""
__version__ = "0.1.0"
