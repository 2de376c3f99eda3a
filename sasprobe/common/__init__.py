"""The ground floor: what every layer may use (the one-line user error, opening a file a
user named, the progress bar). It imports nothing of sasprobe's but itself."""
