"""What every rhbl process stands on, server and clients alike (docs/architecture.md):

- :mod:`process.runtime`: ``run_process`` (logging, signals, exit codes, ``--stats``), the
  liveliness token, the shared report flags.
- :mod:`process.arguments`: argparse types that check a value while parsing (numbers, names,
  endpoints, paths) and refuse it in one line.
- :mod:`process.files`: the file rules (regular files only, atomic replacement, no FIFO or
  device read or written).
- :mod:`process.session`: the one helper that builds zenoh session configs from the flags.

None of it is on the wire: the wire contract is ``protocol/``.
"""
