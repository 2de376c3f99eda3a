"""The browser: a bridge from a running daemon to any number of web pages over WebSocket,
the page's own files (WebGL2 impostors, the backbone trace, the cube, the probe), and a
recorded session as one self-contained HTML file (docs/web.md)."""
