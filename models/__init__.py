"""The shipped robot (MJCF): package data read through importlib.resources; see README.md here."""
