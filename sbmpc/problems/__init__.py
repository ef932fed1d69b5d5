from dynamics._jitcache import refresh_once

refresh_once()     # numba's cache, consistent across files (dynamics._jitcache)
