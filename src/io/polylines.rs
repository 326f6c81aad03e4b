//! Polylines as OBJ line elements (`v` records, then one `l` record per polyline).

use glam::DVec3;
use std::fmt::Write;

pub(crate) fn obj_polylines_bytes(lines: &[Vec<DVec3>]) -> Vec<u8> {
    let mut s = String::from("# trispline polylines\n");
    let mut base = 1usize;
    for line in lines.iter().filter(|l| l.len() >= 2) {
        for p in line {
            let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
        }
        s.push('l');
        for k in 0..line.len() {
            let _ = write!(s, " {}", base + k);
        }
        s.push('\n');
        base += line.len();
    }
    s.into_bytes()
}
