"""Recordings: every message of a run kept as an MCAP file, and what reads, replays and shows it
(docs/recording.md). ``mcap_file`` (the format), ``record`` (``rhbl record``), ``replay``
(``rhbl replay``), ``foxglove_schemas`` (bus messages -> Foxglove's schemas), ``bridge``
(``rhbl foxglove``)."""
