"""Gesture data: the dataset file, simulated users, context sampling and views of clips.

- :mod:`rtcohand_drake.data.dataset`: the HDF5 file of docs/interfaces.md (the gesture dataset file) (write, read, validate)
  and clips at the policy rate.
- :mod:`rtcohand_drake.data.population`: simulated users, hand model and handler labels.
- :mod:`rtcohand_drake.data.generate`: ``python -m rtcohand_drake.data.generate --out PATH.h5``.
- :mod:`rtcohand_drake.data.sampling`: context sampling and the six evaluation settings.
- :mod:`rtcohand_drake.data.plots`, :mod:`rtcohand_drake.data.meshcat_view`: looking at clips.
"""

from rtcohand_drake.data.dataset import (  # noqa: F401
    DIMENSIONS,
    Clip,
    DatasetError,
    PolicyClip,
    load_policy_clips,
    read_dataset,
    write_dataset,
)
