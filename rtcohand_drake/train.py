"""`python -m rtcohand_drake.train`: the command of :mod:`rtcohand_drake.learning.train`."""

from rtcohand_drake.learning.train import entry_point

if __name__ == "__main__":
    entry_point()
