//! Slow and silent clients: a connection that sends nothing, or dribbles
//! its request head, is dropped within a few seconds instead of held
//! forever, and however many of them come, a real request still gets in.

mod support;

use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use jointd::control::Control;
use jointd::http::serve::{serve, FIRST_BYTES, HEADER_READ, MAX_CONNECTIONS};
use jointd::http::{app, AppState};

/// Serves a bus-less daemon through the daemon's own accept loop.
async fn start() -> String {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr").to_string();
    let state = AppState::new(Arc::new(Control::new(Vec::new(), Default::default())), None);
    tokio::spawn(async move {
        serve(listener, app(state), std::future::pending())
            .await
            .expect("serve");
    });
    addr
}

/// Reads until the server closes the connection; how long that took.
async fn until_closed(mut s: TcpStream, bound: Duration) -> Duration {
    let t0 = Instant::now();
    let mut buf = [0u8; 256];
    loop {
        match tokio::time::timeout(bound, s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return t0.elapsed(),
            Ok(Ok(_)) => continue,
            Err(_) => panic!("still open after {bound:?}"),
        }
    }
}

#[tokio::test]
async fn a_silent_connection_is_dropped() {
    let addr = start().await;
    let s = TcpStream::connect(&addr).await.expect("connect");
    let took = until_closed(s, FIRST_BYTES * 4).await;
    assert!(
        took >= FIRST_BYTES / 2,
        "dropped at once ({took:?}): a slow client gets its time"
    );
}

#[tokio::test]
async fn a_request_head_dribbled_forever_is_dropped() {
    let addr = start().await;
    let mut s = TcpStream::connect(&addr).await.expect("connect");
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\n")
        .await
        .expect("write");
    // One more header byte now and then, never the blank line.
    let dribble = tokio::spawn(async move {
        for _ in 0..100 {
            if s.write_all(b"X").await.is_err() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
        s
    });
    let s = dribble.await.expect("dribbler");
    // The dribbler stopped because the server closed its side.
    let took = until_closed(s, HEADER_READ * 4).await;
    assert!(took < HEADER_READ * 4);
}

#[tokio::test]
async fn silent_connections_beyond_the_cap_cannot_keep_a_request_out() {
    let addr = start().await;
    let mut silent = Vec::with_capacity(MAX_CONNECTIONS + 16);
    for _ in 0..MAX_CONNECTIONS + 16 {
        match TcpStream::connect(&addr).await {
            Ok(s) => silent.push(s),
            Err(_) => break,
        }
    }
    // Within the silent ones' deadline, a real request gets an answer.
    let deadline = Instant::now() + FIRST_BYTES * 6;
    loop {
        let answered = async {
            let mut s = TcpStream::connect(&addr).await.ok()?;
            s.write_all(b"GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
                .await
                .ok()?;
            let mut out = Vec::new();
            s.read_to_end(&mut out).await.ok()?;
            Some(String::from_utf8_lossy(&out).starts_with("HTTP/1.1 200"))
        }
        .await;
        if answered == Some(true) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no answer while {} connections sat silent",
            silent.len()
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    drop(silent);
}
