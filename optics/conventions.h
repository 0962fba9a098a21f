// hsd optics conventions (stated once; every optics file follows them).
//
// Units      SI inside: metres, radians; wavelengths in metres (configs list band
//            centres in nm as optics.wavelengths_nm and convert at the edge).
// Time       Fields carry exp(−iωt); a wave travelling +z is exp(+ikz), so extra
//            optical path adds phase. A DOE of height h [m] and index η adds
//            φ = k (η − 1) h (thicker = more delay); a converging lens of focal
//            length f is exp(−i k r²/(2f)).
// Source     On the optical axis at distance z [m] in front of the DOE; its
//            paraxial spherical wave at the DOE is exp(+i k r²/(2z)). The paper
//            prints r²/z; the 1/2 is the paraxial expansion of √(r²+z²) − z.
// Sensor     At distance s [m] behind the DOE. Fresnel propagation:
//              U_s(x, y) = e^{iks} e^{ik(x²+y²)/(2s)} / (iλs)
//                          ∬ U(ξ, η) e^{ik(ξ²+η²)/(2s)} e^{−i2π(xξ + yη)/(λs)} dξ dη
//            and intensity I = |U_s|² (computed as re² + im²).
// Axes       x grows with the column index, y with the row index, in every array
//            (DOE grid, PSF window, images). DOE sample [i, j] sits at
//            x = (j − (N−1)/2)·δ, y = (i − (N−1)/2)·δ. PSF pixel [r, c] of an odd
//            window of size P has its centre at x = (c − P//2)·p, y = (r − P//2)·p:
//            the optical axis is the centre of pixel [P//2, P//2].
// Tensors    PSF stacks are [L, Z, P, P] (wavelength, depth, y, x); images [B, C, H, W].
// Precision  Phase arguments are formed in float64 and wrapped to [−π, π) before
//            any cast to float32; no complex abs (NaN gradient at 0).
#pragma once
