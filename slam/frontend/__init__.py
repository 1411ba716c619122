"""Laser front-end: scans prepared and registered by KISS-ICP, in a second process beside reading."""
