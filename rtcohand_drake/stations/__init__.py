"""Stations: the arm behind one port set (`rtcohand_drake.interfaces.STATION_INPUTS/OUTPUTS`).

    sim.py                  make_sim_station: the simulated Gen3 MultibodyPlant
    kortex.py               make_kortex_station: the real arm (Drake side)
    kortex_session.py       the Kortex API session and unit conversions (no Drake)
    fake_kortex_arm.py      a stand-in for the physical arm behind the Kortex API, for tests
    kinematic_workpiece.py  a stand-in that moves the part exactly as commanded, for tests
"""
