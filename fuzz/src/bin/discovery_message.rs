//! Every discovery datagram body (`wire::decode`: Solicit, Announce, Withdraw, Bye) and the
//! domain check (`wire::decode_for_domain`). A datagram that decodes is encoded again and
//! must decode to the same header and message.

use ndds_core::wire::{self, DropReason, MAX_DATAGRAM};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let decoded = wire::decode(data);
        if let Ok((header, _)) = &decoded {
            assert!(wire::decode_for_domain(data, header.domain).is_ok());
            assert_eq!(
                wire::decode_for_domain(data, header.domain.wrapping_add(1)).err(),
                Some(DropReason::OtherDomain)
            );
        }
        let Ok((header, message)) = decoded else {
            return;
        };
        let mut again = Vec::new();
        match wire::encode(header.domain, header.sender, &message, &mut again) {
            Ok(()) => {
                let (header2, message2) =
                    wire::decode(&again).expect("a re-encoded message decodes");
                assert_eq!(header2, header);
                assert_eq!(message2, message);
            }
            // The canonical encoding is never longer than the one that decoded.
            Err(err) => assert!(data.len() > MAX_DATAGRAM, "re-encoding failed: {err}"),
        }
    });
}
