"""Settings per environment: ``dev`` (one machine, the default), ``prod`` and ``test``."""
