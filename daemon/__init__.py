"""The device daemon: the process (service, requests, loop, control, publisher, events), the
haptic rendering it runs each tick (haptics/) and session recording and replay
(recording/)."""
