"""The top floor: the `sasprobe` command (entry point, commands, configuration, argument
types), the demo and the benchmarks. It may import every layer; nothing imports it."""
