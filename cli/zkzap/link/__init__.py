"""The link layer: ports opened by URL, transactions, timeouts, echo handling.

- :mod:`.port`          ``open_port``: device paths and every pyserial URL, plus ``sim://``
- :mod:`.protocol_sim`  the ``sim://`` URL handler (a simulator in-process)
"""
