"""The boxes of the run diagram, one Drake system per module.

    gestures/                 gesture sources (base, replay, camera, simulated person) and their registry
    policy.py                 CchpPolicy: the exported TorchScript CCHP as a LeafSystem
    moving_average_downsampler.py   MovingAverageDownsampler: predictions -> twist request
    safety/                   SafetySupervisor and its rules (one function and one flag each)
    diff_ik.py                TwistToJointVelocity: twist -> joint velocities
    operator_panel.py         pause and sensitivity (Meshcat panel, or a schedule)
    scripted_twist.py         ScriptedTwist: the scenario's scripted motion, no policy
    overlay.py                RunOverlay: hand, twist and status in Meshcat

Each system takes its own config dataclass (defined beside it); the scenario
(`rtcohand_drake.scenario`) composes them. Port names: `rtcohand_drake.interfaces`.
"""
