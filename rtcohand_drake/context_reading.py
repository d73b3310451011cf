"""`python -m rtcohand_drake.context_reading`: the command of :mod:`rtcohand_drake.analysis.context_reading`."""

from rtcohand_drake.analysis.context_reading import entry_point

if __name__ == "__main__":
    entry_point()
