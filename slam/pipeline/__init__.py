"""One run end to end: the in-memory core and the result folder around it."""
