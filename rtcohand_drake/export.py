"""`python -m rtcohand_drake.export`: the command of :mod:`rtcohand_drake.learning.export`."""

from rtcohand_drake.learning.export import entry_point

if __name__ == "__main__":
    entry_point()
