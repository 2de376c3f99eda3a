"""Device-side emulators speaking the public wire protocols, for tests.

Serial devices sit behind a real pty pair (pyserial opens the tty path), the Falcon
behind a pyusb backend (pyusb's own code runs), the SpaceMouse behind a fake at the
hidapi boundary, the OpenHaptics arm behind a fake vendor library built from C.
"""
