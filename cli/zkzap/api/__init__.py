"""The zkzap library: the public, click-free Python API under the command line.

Layers, bottom up: :mod:`zkzap.codec` (pure protocol tables and codecs) -> :mod:`zkzap.link`
(ports by URL, transactions) -> :mod:`zkzap.api` (sessions and procedures: what users call) ->
:mod:`zkzap.io` (writers by format, bridges) -> :mod:`zkzap.commands` (options -> API -> render).

Nothing in this package imports click or rich; pyserial is imported only when a port opens.
"""
