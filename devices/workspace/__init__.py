"""Where the arm's workspace lies in the molecule: the mapping the haptic engine maps every
tip through (mapping.py) and the cube a session starts with (start.py).

It sits with the devices, below the daemon's engine, because two layers need the same
start (a fact two layers need lives in the lower one): the engine maps the tip through it
every tick, and the simulated arm (devices/simulated/) places its scripted hand on the
molecule with the mapping a session starts with.
"""
