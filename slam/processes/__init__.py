"""How gslam uses processes: work on the second core, and how Ctrl-C and the signals that end a process stop a command."""
