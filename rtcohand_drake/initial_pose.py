"""`python -m rtcohand_drake.initial_pose`: the command of :mod:`rtcohand_drake.cell.initial_pose`."""

from rtcohand_drake.cell.initial_pose import entry_point

if __name__ == "__main__":
    entry_point()
