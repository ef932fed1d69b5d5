"""What the compiled search reports back: the status of a chunk of expansions and the
counters (an int64 array) it keeps, shared by the search and its open set."""

# ---- status of a chunk -----------------------------------------------------------
RUNNING, FOUND, EXHAUSTED, ITERATIONS, GROW = 0, 1, 2, 3, 4
# ---- counters (int64 array) ------------------------------------------------------
C_NODES, C_HEAP, C_ITERS, C_EDGES, C_SEQ, C_GOAL, C_DEPTHCUT, C_FIRST, C_SIMULATED, C_STALE = range(10)
# C_EDGES: edges merged (nbranch per expansion); C_SIMULATED: edges simulated (more in a
# batched search, which simulates the edges of nodes it may never expand); C_STALE: nodes
# whose edges were simulated ahead from a state a cheaper arrival then replaced
C_INVALID = 10         # C_INVALID + k counts edges rejected with code -k (k = 1..MAX_CODE)
MAX_CODE = 8
NC = C_INVALID + MAX_CODE + 1


def budget_text(seconds: float) -> str:
    """A time budget [s] as the search's messages write it: three significant digits
    below 100 s (0.0175, 2.5, 57.8), whole seconds above (120, 86400)."""
    return f"{seconds:.3g}" if seconds < 100 else f"{seconds:.0f}"
