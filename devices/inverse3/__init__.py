"""Haply Inverse3 arms through Haply's Inverse Service (its WebSocket simulation channel).

`protocol` holds the 3.x JSON messages and the one mapping from Haply's frame to
sasprobe's, `models` what is assumed of each arm, `driver` the device.
"""
