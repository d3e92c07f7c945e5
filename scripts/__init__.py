"""The command line (``eyemech``): parsing, then a call into ``eyemech.problems``."""
