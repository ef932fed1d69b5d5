from dynamics._cache import refresh_once

refresh_once()     # numba's cache, consistent across files (dynamics/_cache.py)
