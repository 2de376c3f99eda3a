"""Haply 2DIY (generations 2 and 3) on the Haply M0/M3 board firmware.

`models.py` holds the generations, `protocol.py` the board's byte protocol,
`kinematics.py` Haply's pantograph solution and the frame, `driver.py` the device.
"""
