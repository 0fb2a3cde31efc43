//! Async port calls start no thread: many pending `send_async` calls on one single-threaded
//! executor leave the process's thread count as it was (but for the one port timer thread).
//! Alone in its test binary, so no other test's threads are counted.

mod common;

use std::sync::Arc;
use std::time::Duration;

use ndds_client::ports::{PortOwner, PortUser};

const WAIT: Duration = Duration::from_secs(10);

fn thread_count() -> usize {
    std::fs::read_dir("/proc/self/task").unwrap().count()
}

#[test]
fn async_forms_start_no_thread_per_call() {
    let dir = tempfile::tempdir().unwrap();
    let p = common::participant(&common::unique_config(dir.path(), "async-threads"));
    let owner = Arc::new(PortOwner::<u32, u32>::declare(&p, "async.threads", "server").unwrap());
    let user = Arc::new(PortUser::<u32, u32>::declare(&p, "async.threads", "client").unwrap());
    // One exchange first: the owner and the user have found each other.
    let warm = {
        let user = Arc::clone(&user);
        std::thread::spawn(move || user.send(&0, WAIT))
    };
    let (_, reply) = owner.receive(WAIT).unwrap();
    reply.reply(&0).unwrap();
    warm.join().unwrap().unwrap();
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let threads = thread_count();
    let calls = 16;
    let (grown, replies) = runtime.block_on(async {
        let pending: Vec<_> = (0..calls)
            .map(|i| tokio::spawn(user.send_async(i, WAIT)))
            .collect();
        // Let every send go out and wait for its reply.
        tokio::time::sleep(Duration::from_millis(300)).await;
        let grown = thread_count().saturating_sub(threads);
        for _ in 0..calls {
            let (n, reply) = owner.receive_async(WAIT).await.unwrap();
            reply.reply(&(n * 10)).unwrap();
        }
        let mut replies = Vec::new();
        for call in pending {
            replies.push(call.await.unwrap().unwrap());
        }
        (grown, replies)
    });
    assert_eq!(replies, (0..calls).map(|i| i * 10).collect::<Vec<_>>());
    // At most the process's one port timer thread may have started.
    assert!(
        grown <= 1,
        "{grown} threads started for {calls} async sends"
    );
}
