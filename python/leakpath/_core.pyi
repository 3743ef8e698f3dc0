"""Type stubs for leakpath's compiled Rust core (``leakpath._core``)."""

import numpy as np
import numpy.typing as npt

__version__: str

def kernel_table(ny: int, nx: int, dx: float, e_star: float) -> npt.NDArray[np.float64]:
    """Love influence table ``K[|di|, |dj|]``, shape ``(ny, nx)``.

    Displacement at the centre of an element ``di`` rows and ``dj`` columns away from a
    ``dx × dx`` element under unit uniform pressure, on a half-space of contact modulus
    ``e_star``. ``K[0, 0] = 4·dx·ln(1 + √2)/(π E*)``; far away ``K → dx²/(π E* r)``.
    """
