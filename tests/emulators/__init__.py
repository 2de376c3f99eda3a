"""Device-side emulators speaking the public wire protocols, for tests.

Serial devices sit behind a real pty pair (pyserial opens the tty path), the Falcon
behind a pyusb backend (pyusb's own code runs), the SpaceMouse on emulated hidraw
nodes behind a stand-in for the hidapi module, the OpenHaptics arm behind a stand-in
vendor library built from C. They are written from the makers' public sources and
import nothing from sasprobe (tests/test_project_emulators_independent.py checks it).
"""
