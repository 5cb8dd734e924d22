use mie::*;
use num_complex::Complex64;
use std::time::Instant;
fn main() {
    let x = 1e5;
    let t = Instant::now();
    let s = Sphere::new(Complex64::new(1.333, 1e-8), x).unwrap();
    let c = s.coefficients();
    eprintln!("coefficients {:?}", t.elapsed());
    let t = Instant::now();
    let e = c.efficiencies();
    eprintln!("efficiencies {:?}", t.elapsed());
    let t = Instant::now();
    let terms = SphereTerms::new(&c);
    eprintln!("terms {:?}", t.elapsed());
    let mu = AngleGrid::new(0.18).unwrap().cosines();
    let t = Instant::now();
    let f = FoldedAngles::new(&mu);
    let (s1, _s2) = amplitudes(&c, &f);
    eprintln!("amplitudes {:?} {}", t.elapsed(), s1[0].re / e.q_ext);
    let _ = terms;
}
