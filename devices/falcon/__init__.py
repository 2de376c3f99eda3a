"""Novint Falcon over USB (its FTDI bridge, 0403:CB48) through pyusb, after libnifalcon.

models (the numbers), kinematics (Stamper), protocol (frames, loader bytes), ftdi (the
USB-serial bridge and its asynchronous I/O), loader (firmware upload), driver (the device).
"""
