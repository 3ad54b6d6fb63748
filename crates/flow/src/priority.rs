//! Thread priorities: background work yields the CPU to the spoken turn on a busy machine.
//!
//! On a small machine shared with other work, the work of the current turn (audio in, voice activity, the final
//! decode, the rule, the first sentence, the first audio) must run before background work (vision beyond what gaze
//! needs, recording). Linux schedules threads by their nice level, and a thread may always lower its own priority
//! (raise its nice value) without privileges; raising it needs `CAP_SYS_NICE` or an `RLIMIT_NICE`, which a service
//! unit may grant (docs/deploy.md). So background threads lower themselves, and nothing here asks for more.

/// The nice level of background threads: on a contended core a nice-0 thread gets about nine times the CPU of a
/// nice-10 one (the kernel's weights 1024 against 110).
pub const BACKGROUND_NICE: i32 = 10;

/// Why a thread's priority could not be read or lowered.
#[derive(Debug, thiserror::Error)]
#[error("thread priority: {0}")]
pub struct PriorityError(#[from] rustix::io::Errno);

/// The calling thread's nice level (-20 most favoured .. 19 least).
pub fn this_thread_nice() -> Result<i32, PriorityError> {
    let tid = rustix::thread::gettid();
    Ok(rustix::process::getpriority_process(Some(tid))?)
}

/// Lowers the calling thread to nice level `nice` if it is above it; never raises it. Threads it starts later
/// inherit the level (an ONNX Runtime or OpenCV pool created from it runs in the background too). Returns the
/// level the thread has afterwards.
pub fn lower_this_thread(nice: i32) -> Result<i32, PriorityError> {
    let now = this_thread_nice()?;
    if now >= nice {
        return Ok(now);
    }
    // Linux's setpriority(PRIO_PROCESS, tid) sets one thread's nice level (threads are tasks with their own).
    rustix::process::setpriority_process(Some(rustix::thread::gettid()), nice)?;
    this_thread_nice()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_lowers_itself_and_the_threads_it_starts_inherit_it_while_others_keep_theirs() {
        let before = this_thread_nice().expect("read the test thread's level");
        let (own, child) = std::thread::spawn(|| {
            let own = lower_this_thread(BACKGROUND_NICE).expect("lowering needs no privilege");
            let child = std::thread::spawn(|| this_thread_nice().expect("child level"))
                .join()
                .expect("child thread");
            (own, child)
        })
        .join()
        .expect("background thread");
        assert_eq!(own, BACKGROUND_NICE.max(before));
        assert_eq!(
            child, own,
            "a thread started by a background thread is background too"
        );
        assert_eq!(
            this_thread_nice().expect("read again"),
            before,
            "only the thread that asked was lowered"
        );
    }

    #[test]
    fn a_thread_already_lower_is_never_raised() {
        let level = std::thread::spawn(|| {
            lower_this_thread(15).expect("to 15");
            lower_this_thread(BACKGROUND_NICE).expect("asking for 10 afterwards")
        })
        .join()
        .expect("thread");
        assert_eq!(level, 15);
    }
}
