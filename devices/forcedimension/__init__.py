"""Force Dimension arms through the vendor's DHD library.

`dhd` holds the library's constants and signatures (the public header dhdc.h), `models`
the per-model limits (CHAI3D's table), `frame` the one mapping from DHD's frame to
sasprobe's, `driver` the device.
"""
