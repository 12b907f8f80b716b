"""servoscope: frequency response and transfer functions of actuators, measured from video."""

__version__ = "0.1.0"
