//! IPC frame bodies from a client or tool to its daemon (`ipc::decode_body::<ClientMessage>`): what a
//! peer on the Unix socket can send. A body that decodes encodes again (`encode_body`) and
//! decodes to the same message.

use ndds_core::ipc::{ClientMessage, decode_body, encode_body};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Ok(message) = decode_body::<ClientMessage>(data) else {
            return;
        };
        let body = encode_body(&message).expect("a decoded message encodes");
        let again = decode_body::<ClientMessage>(&body).expect("an encoded message decodes");
        assert_eq!(again, message);
    });
}
