//! IPC frame bodies from the daemon to its client (`ipc::decode_body::<DaemonMessage>`): what a
//! peer on the Unix socket can send. A body that decodes encodes again (`encode_body`) and
//! decodes to the same message.

use ndds_core::ipc::{DaemonMessage, decode_body, encode_body};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Ok(message) = decode_body::<DaemonMessage>(data) else {
            return;
        };
        let body = encode_body(&message).expect("a decoded message encodes");
        let again = decode_body::<DaemonMessage>(&body).expect("an encoded message decodes");
        assert_eq!(again, message);
    });
}
