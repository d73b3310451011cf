"""The learning pipeline: networks, training, evaluation and export. No Drake here (a test checks).

    nets/          CCHP, RANP, Dummy LSTM and their shared blocks
    batching.py    target clips and context pieces -> padded tensors with masks
    checkpoint.py  training checkpoints
    train.py, evaluate.py, export.py, policy_file.py
"""
