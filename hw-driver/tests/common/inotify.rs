//! A minimal inotify(7) reader: the fake sysfs tree learns of each write (and when it
//! happened) the way the kernel's PWM driver would see it, without polling files.

use std::ffi::CString;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::path::Path;
use std::time::Duration;

/// One event: the watch it came from, its mask and the file name inside the watched dir.
#[derive(Debug, Clone)]
pub struct Event {
    pub wd: i32,
    pub mask: u32,
    pub name: String,
}

pub struct Inotify {
    fd: OwnedFd,
}

impl Inotify {
    pub fn new() -> Inotify {
        // SAFETY: plain syscall; the returned fd is checked and owned below.
        let fd = unsafe { libc::inotify_init1(libc::IN_CLOEXEC | libc::IN_NONBLOCK) };
        assert!(
            fd >= 0,
            "inotify_init1: {}",
            std::io::Error::last_os_error()
        );
        // SAFETY: fd is a fresh descriptor nobody else owns.
        Inotify {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
        }
    }

    /// Watches `dir` for files closed after writing (one event per `echo v > file`).
    pub fn watch_writes(&self, dir: &Path) -> i32 {
        let c = CString::new(dir.as_os_str().as_bytes()).unwrap();
        // SAFETY: valid fd and NUL-terminated path.
        let wd = unsafe {
            libc::inotify_add_watch(self.fd.as_raw_fd(), c.as_ptr(), libc::IN_CLOSE_WRITE)
        };
        assert!(
            wd >= 0,
            "inotify_add_watch {}: {}",
            dir.display(),
            std::io::Error::last_os_error()
        );
        wd
    }

    /// Events that arrive within `timeout` (empty on timeout).
    pub fn read(&self, timeout: Duration) -> Vec<Event> {
        let mut pfd = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ms = timeout.as_millis().min(i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd.
        let n = unsafe { libc::poll(&mut pfd, 1, ms) };
        if n <= 0 {
            return Vec::new();
        }
        let mut buf = [0u8; 4096];
        // SAFETY: buf is valid for its length.
        let len = unsafe { libc::read(self.fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
        if len <= 0 {
            return Vec::new();
        }
        let mut out = Vec::new();
        let mut off = 0usize;
        let header = std::mem::size_of::<libc::inotify_event>();
        while off + header <= len as usize {
            // SAFETY: the kernel wrote a whole inotify_event at `off`; read it unaligned.
            let ev: libc::inotify_event =
                unsafe { std::ptr::read_unaligned(buf[off..].as_ptr().cast()) };
            let name_bytes = &buf[off + header..off + header + ev.len as usize];
            let name = String::from_utf8_lossy(name_bytes)
                .trim_end_matches('\0')
                .to_string();
            out.push(Event {
                wd: ev.wd,
                mask: ev.mask,
                name,
            });
            off += header + ev.len as usize;
        }
        out
    }
}
