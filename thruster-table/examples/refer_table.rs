//! Prints the referral of commands from 16 V to another voltage (a look at the table's map).
use thruster_table::ThrusterTable;
fn main() {
    let t = ThrusterTable::t200();
    for v in [16.64, 13.7] {
        println!("V = {v}");
        let mut prev = f64::NAN;
        for i in -100..=100 {
            let u = i as f64 / 100.0;
            let out = t.refer_command(u, 16.0, v);
            if i % 5 == 0 || (out - prev).abs() > 0.03 {
                println!(
                    "  u {u:+.2} -> {out:+.4}  (thrust ref {:.3} N, at V {:.3} N)",
                    t.thrust_at_command(16.0, u),
                    t.thrust_at_command(v, out)
                );
            }
            prev = out;
        }
    }
}
