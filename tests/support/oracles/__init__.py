"""Reference ("oracle") implementations the tests compare production code against.

They were the production code's scalar forms before issue 10 made the batched implementations
the only production path (``quadloc.factors.overlap``, ``quadloc.factors.metrics``); kept here
verbatim, one pair at a time, as independent checks.
"""
