// Pixel kinds of the G-buffer's second id channel (render/targets.py: KIND_*).
#define KIND_BACKGROUND 0
#define KIND_SPHERE 1
#define KIND_CAP 2
#define KIND_BACKBONE 3
#define KIND_PROBE 4
