"""PHANTOM Omni / Touch and other HDAPI arms through the vendor's OpenHaptics HD library.

`hdapi` holds the library's constants, signatures and error classes (the public
headers), `driver` the device (the SDK examples' calibration and error handling).
"""
