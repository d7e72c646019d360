//! The per-sample path allocates nothing: a counting global allocator watches the state machine
//! answer IMU samples while idle, pulsing and controlling.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use thrusterd_core::machine::{Geometry, ImuInput, Machine, MachineSetup, Request, State};

struct Counting;

static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn sample(k: u64) -> ImuInput {
    ImuInput {
        seq: k,
        t_ns: 1_000_000_000 + k * 5_000_000,
        gyro: [0.001 * (k % 5) as f64, -0.002, 0.001],
        accel: [0.0, 0.01 * (k % 3) as f64, -9.80665],
        mag: Some([20.0, 0.0, 45.0]),
        depth: Some(5.0),
    }
}

/// Allocations made by `ticks` samples starting at `k`.
fn count(machine: &mut Machine, k: &mut u64, ticks: u64) -> u64 {
    ALLOCS.store(0, Ordering::SeqCst);
    COUNTING.store(true, Ordering::SeqCst);
    for _ in 0..ticks {
        *k += 1;
        std::hint::black_box(machine.on_imu(&sample(*k)));
    }
    COUNTING.store(false, Ordering::SeqCst);
    ALLOCS.load(Ordering::SeqCst)
}

#[test]
fn answering_a_sample_does_not_allocate() {
    let geometry = Geometry {
        positions: vec![
            [0.0, -0.2, 0.0],
            [0.0, 0.2, 0.0],
            [-0.2, -0.15, 0.0],
            [-0.2, 0.15, 0.0],
        ],
        directions: vec![
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.0, 0.0, -1.0],
        ],
    };
    let mut m = Machine::new(MachineSetup {
        thrusters: 4,
        geometry: Some(geometry),
        ..MachineSetup::default()
    });
    let mut k = 0;
    count(&mut m, &mut k, 10); // attitude filter initialised
    assert_eq!(count(&mut m, &mut k, 200), 0, "idle");

    m.on_request(Request::Hold).unwrap();
    count(&mut m, &mut k, 2); // first control tick captures the target
    assert_eq!(m.state(), State::Active);
    assert_eq!(count(&mut m, &mut k, 500), 0, "controlling");

    m.on_request(Request::Estimate).unwrap();
    // Through the noise phase into the first pulse; pulse starts and ends allocate (once per
    // pulse), the samples in between must not.
    while m.state() != State::Pulse {
        k += 1;
        m.on_imu(&sample(k));
    }
    assert_eq!(count(&mut m, &mut k, 10), 0, "inside a pulse");
}
