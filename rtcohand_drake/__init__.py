"""Real-time gesture control of a Kinova Gen3 holding a workpiece (Drake + CCHP)."""

__version__ = "0.1.0"
