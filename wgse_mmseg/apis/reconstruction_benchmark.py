"""``python -m wgse_mmseg.apis.reconstruction_benchmark DATA_ROOT``: the
README's command for the reconstruction benchmark, kept as users know it.
The benchmark itself is :mod:`wgse_mmseg.benchmarks.reconstruction` (same
arguments, same table)."""
from ..benchmarks.reconstruction import main

if __name__ == '__main__':
    main()
