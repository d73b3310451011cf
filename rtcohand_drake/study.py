"""`python -m rtcohand_drake.study`: the command of :mod:`rtcohand_drake.analysis.study`."""

from rtcohand_drake.analysis.study import entry_point

if __name__ == "__main__":
    entry_point()
