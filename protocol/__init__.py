"""Wire protocol between the daemon and renderers: messages, byte layouts, endpoints, security."""
