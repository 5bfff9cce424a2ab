"""Pure math over numpy/torch arrays. Imports nothing else of ``song``."""
