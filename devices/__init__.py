"""Devices: the interface (base.py), the `--device` registry (registry.py), the drivers of
real arms (one package each, with what they share beside them), the simulated arm
(simulated/) and where an arm's workspace lies in the molecule (workspace/). The replay
device is the daemon's (daemon/recording/)."""
