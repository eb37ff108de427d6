"""Reference values for the clear-sky test of src/daylight/clearsky.rs, from pvlib: an
independent implementation of the Ineichen-Perez clear sky, Kasten-Young air mass,
standard-atmosphere pressure and Spencer's extraterrestrial irradiance.

    python3 -m venv /tmp/pv && /tmp/pv/bin/pip install pvlib==0.16.1
    /tmp/pv/bin/python tests/reference/clearsky_pvlib.py

prints, per case: apparent zenith (deg), elevation (m), pressure (mbar), Linke
turbidity, day of the year, [GHI, DNI, DHI] (W/m2). Not run by the test suite (pvlib
pulls in pandas and scipy); the values are pasted into the test with this script's name.
"""
import numpy as np, pvlib
from pvlib import atmosphere, clearsky, irradiance
cases = [(0.0, 0.0, 3.0, 172), (30.0, 0.0, 3.0, 1), (60.0, 1500.0, 2.0, 80), (75.0, 300.0, 4.5, 200), (85.0, 0.0, 3.0, 355), (89.5, 3000.0, 6.0, 300)]
for z, alt, tl, doy in cases:
    am = atmosphere.get_relative_airmass(z, model='kastenyoung1989')
    p = atmosphere.alt2pres(alt)
    ama = atmosphere.get_absolute_airmass(am, p)
    i0 = irradiance.get_extra_radiation(doy, solar_constant=1367.0, method='spencer')
    cs = clearsky.ineichen(np.array([z]), np.array([ama]), np.array([tl]), altitude=alt, dni_extra=i0)
    print(f"({z!r}, {alt!r}, {p/100:.9e}, {tl!r}, {doy}, [{cs['ghi'][0]:.9e}, {cs['dni'][0]:.9e}, {cs['dhi'][0]:.9e}]),")
