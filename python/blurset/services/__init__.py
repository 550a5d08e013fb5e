"""What several commands share and no user imports: the worker process and its devices,
the config and options, outputs and their locks, objects and their checks, publishing,
stop and progress. A service imports public faces and other services, never a command
(`tests/test_package_roles.py`)."""
