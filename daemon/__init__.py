"""The device daemon: haptic rendering of the SAS, the fixed-rate loop, safety, publishing."""
