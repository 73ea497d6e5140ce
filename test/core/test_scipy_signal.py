"""core/scipy_signal.py: scipy.signal imported when first used, never at import, and nothing
of anyone else's imports changed (no stand-in modules)."""
import subprocess
import sys
import textwrap


def test_scipy_signal_is_imported_when_used_and_is_scipys():
    code = textwrap.dedent("""
        import sys
        from road_force_estimator.core import scipy_signal
        assert 'scipy.signal' not in sys.modules
        s = scipy_signal.signal()
        import scipy.signal
        import scipy.stats
        assert s is scipy.signal and scipy.stats.norm.cdf(0.0) == 0.5
        import numpy as np
        x = np.sin(np.arange(400) / 7.0)
        y = s.sosfiltfilt(s.butter(4, 0.1, output='sos'), x)
        print(float(np.max(np.abs(y - x)[100:300])))
    """)
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.split()
    # the zero-phase Butterworth (0.05 cycles/sample) passes sin(k / 7) (0.0227 cycles per
    # sample): |H|^2 = 1 / (1 + 0.455^8) = 0.9982 away from the ends
    assert float(out[0]) < 3e-3
