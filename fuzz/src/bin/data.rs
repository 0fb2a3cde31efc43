//! `Data` datagrams (`wire::DataDatagram::parse` and its submessages: Sample, Fragment,
//! Heartbeat, Gap). A datagram that parses is written again with `DataWriter` from what was
//! decoded, and must parse to the same addressing and submessages.

use ndds_core::wire::data::Addressing;
use ndds_core::wire::{DataDatagram, DataWriter, MAX_DATAGRAM};

fn main() {
    ndds_fuzz::main(|data: &[u8]| {
        let Some((&domain_byte, bytes)) = data.split_first() else {
            return;
        };
        // Most inputs name the domain in their header; the first byte picks the domain the
        // receiver is in, so the other-domain path is reached too.
        let domain = match bytes.get(6..8) {
            Some(d) if domain_byte & 1 == 0 => u16::from_le_bytes([d[0], d[1]]),
            _ => u16::from(domain_byte),
        };
        let Ok(datagram) = DataDatagram::parse(bytes, domain) else {
            return;
        };
        let subs: Vec<_> = datagram
            .subs()
            .take_while(Result::is_ok)
            .flatten()
            .collect();
        if bytes.len() > MAX_DATAGRAM || subs.is_empty() {
            return;
        }
        let mut writer = DataWriter::new();
        let to = Addressing {
            reader_participant: datagram.reader_participant,
            writer: datagram.writer,
            token: datagram.token,
            readers: &datagram.readers,
        };
        writer.begin(domain, datagram.header.sender, &to);
        for sub in &subs {
            assert!(
                writer.push(sub, MAX_DATAGRAM),
                "a decoded submessage is refused"
            );
        }
        let again = DataDatagram::parse(writer.bytes(), domain).expect("re-encoded parses");
        assert_eq!(again.header, datagram.header);
        assert_eq!(again.reader_participant, datagram.reader_participant);
        assert_eq!(again.writer, datagram.writer);
        assert_eq!(again.token, datagram.token);
        assert_eq!(again.readers, datagram.readers);
        let subs2: Vec<_> = again
            .subs()
            .collect::<Result<_, _>>()
            .expect("re-encoded subs decode");
        assert_eq!(subs2, subs);
    });
}
