//! `Feedback` datagrams (`wire::FeedbackDatagram::parse` and its submessages: AckNack and
//! NackFrag, with their bitmaps). A datagram that parses is encoded again with
//! `encode_feedback` from what was decoded, and must parse to the same submessages.

use ndds_core::wire::feedback::{MAX_BITMAP_BYTES, bit, encode_feedback};
use ndds_core::wire::{FeedbackDatagram, FeedbackSub, MAX_DATAGRAM};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Some(domain) = data.get(6..8).map(|d| u16::from_le_bytes([d[0], d[1]])) else {
            return;
        };
        let Ok(datagram) = FeedbackDatagram::parse(data, domain) else {
            return;
        };
        let subs: Vec<_> = datagram
            .subs()
            .take_while(Result::is_ok)
            .flatten()
            .collect();
        for sub in &subs {
            let bitmap = match sub {
                FeedbackSub::AckNack(a) => a.missing,
                FeedbackSub::NackFrag(n) => n.missing,
            };
            assert!(bitmap.len() <= MAX_BITMAP_BYTES);
            // Reading any bit, inside or past the bitmap, is defined.
            let _ = (0..bitmap.len() * 8 + 9)
                .filter(|&i| bit(bitmap, i))
                .count();
        }
        if subs.is_empty() || data.len() > MAX_DATAGRAM {
            return;
        }
        let mut again = Vec::new();
        encode_feedback(
            domain,
            datagram.header.sender,
            datagram.writer_participant,
            datagram.token,
            &subs,
            &mut again,
        )
        .expect("decoded submessages encode");
        let parsed = FeedbackDatagram::parse(&again, domain).expect("re-encoded parses");
        assert_eq!(parsed.header, datagram.header);
        assert_eq!(parsed.writer_participant, datagram.writer_participant);
        assert_eq!(parsed.token, datagram.token);
        let subs2: Vec<_> = parsed
            .subs()
            .collect::<Result<_, _>>()
            .expect("re-encoded subs decode");
        assert_eq!(subs2, subs);
    });
}
