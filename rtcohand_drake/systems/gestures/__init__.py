"""Gesture sources: systems that output what the policy reads.

`base` holds the shared ports and the keypoint base class; `replay`, `camera`
and `simulated_person` are the sources; `registry` names them for the run
command (`--gesture-source NAME`).
"""
