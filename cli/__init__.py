"""The ``wholearm`` command line: click commands only, over the public wholearm_tools API."""
