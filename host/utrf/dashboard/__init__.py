"""``utrf dashboard``: the hand in a browser, built on NiceGUI (``docs/dashboard.md``).

:mod:`~utrf.dashboard.hub` holds what every page shares and does (the Hand, the stream's
recent samples, who controls, the commands, recording), with no web code; :mod:`~utrf.dashboard.
settings` checks settings against the protocol's ranges; :mod:`~utrf.dashboard.access` the
token rule; :mod:`~utrf.dashboard.page` and :mod:`~utrf.dashboard.hand3d` are the page;
:mod:`~utrf.dashboard.server` runs it. Needs the ``dashboard`` extra."""
