"""Where results go: the --out rule, result markers, temporary folders and atomic writes."""
