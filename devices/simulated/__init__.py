"""The simulated arm: the model of an Omni-class arm held by a hand (arm.py), and the paths
the hand follows over the molecule, one per script (hand_paths.py)."""
