"""kitegully: kite and drone photogrammetry for soil-erosion mapping.

Subpackages each have one concern: ``tether`` (kite line and flight planning),
``twin`` (synthetic sites), ``sfm``, ``georef``, ``dense``, ``terrain``, ``gully``,
``obia``, ``evaluate`` and ``io``. The shape every stage package follows is written down
in docs/architecture.md.
"""

__version__ = "0.1.0"


class InputError(ValueError):
    """Bad input: the message names the file (or config key) and what is wrong.

    Workflow scripts let this propagate so the rule stops with one clear sentence.
    """
