"""Independent references the tests compare sasprobe against: CPU ray tracers, occlusion and
lighting in float64 numpy, the haptic surface's signed distance, a pose decoder from
protocol/README.md. Each is written from the mathematics or the published description and
shares no code with what it checks (it may take shared constants and input types)."""
