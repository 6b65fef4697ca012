"""The `teleprev` command line: one small module per command group, registered in app.py."""
