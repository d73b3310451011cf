"""`python -m rtcohand_drake.evaluate`: the command of :mod:`rtcohand_drake.learning.evaluate`."""

from rtcohand_drake.learning.evaluate import entry_point

if __name__ == "__main__":
    entry_point()
