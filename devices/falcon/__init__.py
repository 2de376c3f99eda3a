"""Novint Falcon over USB (its FTDI bridge, 0403:CB48) through pyusb, after libnifalcon.

models (the numbers), kinematics (Stamper), protocol (frames, loader bytes), ftdi (the
USB-serial bridge and its asynchronous I/O), loader (firmware upload), driver (the device).
"""

from sasprobe.devices.falcon.driver import FalconDevice, create
from sasprobe.devices.falcon.models import PRODUCT_ID, VENDOR_ID

__all__ = ["FalconDevice", "create", "VENDOR_ID", "PRODUCT_ID"]
