"""The live map: its web server and the page it serves (static/)."""
