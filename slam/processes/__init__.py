"""How gslam uses processes: work on the second core, and how Ctrl-C, SIGTERM and SIGHUP stop a command."""
