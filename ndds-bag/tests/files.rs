//! Bag files without a network: what the writer writes the reader reads back; split files;
//! a truncated file read up to where it ends; a file of another encoding refused naming the
//! channel; filter and cut; the disk reserve.

use std::path::Path;
use std::time::Duration;

use ndds_bag::edit::{Keep, rewrite};
use ndds_bag::format::ChannelMeta;
use ndds_bag::info::BagInfo;
use ndds_bag::write::{BagWriter, Compression, Lost, Record, WriteOptions};
use ndds_bag::{BagError, BagReader, Ending, Merged};
use ndds_core::types::TypeDescription;
use ndds_core::wire::{Guid, Reliability};

const SECOND: u64 = 1_000_000_000;
const T0: u64 = 1_800_000_000 * SECOND;

fn writer_meta(entity: u32) -> ChannelMeta {
    ChannelMeta {
        writer: Some(Guid {
            participant: 0xfeed,
            entity,
        }),
        strength: 3,
        persistence: Duration::from_millis(100),
        reliability: Reliability::Reliable { depth: 16 },
    }
}

/// Writes `count` u64 samples on `topic` every 10 ms from `T0`, and as many (f64, String)
/// samples on `other`.
fn write_bag(path: &Path, options: WriteOptions, count: u64) -> BagWriter {
    let mut writer = BagWriter::create(path, options).unwrap();
    let a = writer.add_channel("a/u64", &TypeDescription::of::<u64>(), writer_meta(1));
    let b = writer.add_channel(
        "b/pair",
        &TypeDescription::of::<(f64, String)>(),
        ChannelMeta::default(),
    );
    for i in 0..count {
        let t = T0 + i * SECOND / 100;
        writer
            .write(Record {
                channel: a,
                seq: i + 1,
                log_time: t,
                publish_time: t - 1000,
                data: &postcard::to_allocvec(&i).unwrap(),
            })
            .unwrap();
        writer
            .write(Record {
                channel: b,
                seq: i + 1,
                log_time: t + 1,
                publish_time: t,
                data: &postcard::to_allocvec(&(i as f64, format!("n{i}"))).unwrap(),
            })
            .unwrap();
    }
    writer
}

fn read_all(path: &Path) -> (Vec<ndds_bag::BagMessage>, Ending) {
    let mut reader = BagReader::open(path).unwrap();
    let mut messages = Vec::new();
    while let Some(message) = reader.next_message().unwrap() {
        messages.push(message);
    }
    (messages, reader.ending().clone())
}

#[test]
fn what_is_written_reads_back_with_types_qos_times_and_losses() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.mcap");
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let _ = std::fs::remove_file(&path);
        let mut writer = write_bag(
            &path,
            WriteOptions {
                compression,
                ..WriteOptions::default()
            },
            300,
        );
        writer.note_lost(
            "a/u64",
            Lost {
                gaps: 4,
                overflow: 2,
            },
        );
        writer.finish().unwrap();
        let (messages, ending) = read_all(&path);
        assert_eq!(ending, Ending::Complete);
        assert_eq!(messages.len(), 600);
        let a: Vec<u64> = messages
            .iter()
            .filter(|m| m.channel.topic == "a/u64")
            .map(|m| postcard::from_bytes(&m.data).unwrap())
            .collect();
        assert_eq!(a, (0..300).collect::<Vec<_>>());
        let first = &messages[0];
        assert_eq!(first.log_time, T0);
        assert_eq!(first.publish_time, T0 - 1000);
        assert_eq!(first.sequence, 1);
        assert_eq!(first.channel.meta, writer_meta(1));
        assert_eq!(
            first.channel.desc.as_ref().unwrap(),
            &TypeDescription::of::<u64>()
        );
        let info = BagInfo::read(&path).unwrap();
        assert!(info.finished);
        assert_eq!(info.messages, 600);
        assert_eq!(info.topics["a/u64"].lost.total(), 6);
        assert_eq!(info.topics["b/pair"].type_name, "(f64, String)");
        assert!(
            (info.duration_s() - 2.99).abs() < 0.01,
            "{}",
            info.duration_s()
        );
        let name = match compression {
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
            Compression::None => "",
        };
        assert!(info.chunks.contains_key(name), "{:?}", info.chunks);
    }
    // Never over an existing file.
    assert!(matches!(
        BagWriter::create(&path, WriteOptions::default()),
        Err(BagError::Exists(_))
    ));
}

#[test]
fn split_files_by_size_and_by_duration_hold_everything_between_them() {
    let dir = tempfile::tempdir().unwrap();
    for (name, options) in [
        (
            "by_size",
            WriteOptions {
                max_size: Some(16 << 10),
                chunk_size: 4 << 10,
                compression: Compression::None,
                ..WriteOptions::default()
            },
        ),
        (
            "by_time",
            WriteOptions {
                max_duration: Some(Duration::from_secs(1)),
                ..WriteOptions::default()
            },
        ),
    ] {
        let path = dir.path().join(name);
        let mut writer = write_bag(&path, options, 1000);
        writer.finish().unwrap();
        let files = writer.files().to_vec();
        assert!(files.len() >= 3, "{name}: {files:?}");
        assert_eq!(files[0], path.join(format!("{name}_0.mcap")));
        // Every file is whole, and merged they give every message in time order.
        for file in &files {
            assert_eq!(read_all(file).1, Ending::Complete, "{}", file.display());
        }
        let mut merged = Merged::open(&files).unwrap();
        let mut times = Vec::new();
        while let Some((message, _)) = merged.next_message().unwrap() {
            times.push(message.log_time);
        }
        assert_eq!(times.len(), 2000, "{name}");
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "{name}: in order");
        if name == "by_time" {
            // 10 s of samples in files of at most 1 s each.
            assert_eq!(files.len(), 10, "{files:?}");
        }
    }
}

#[test]
fn a_truncated_file_reads_up_to_where_it_ends_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("whole.mcap");
    let mut writer = write_bag(
        &path,
        WriteOptions {
            chunk_size: 4 << 10,
            ..WriteOptions::default()
        },
        2000,
    );
    writer.finish().unwrap();
    let whole = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    // Cut in the middle (a recorder killed with -9 leaves no summary).
    std::fs::write(&cut, &whole[..whole.len() / 2]).unwrap();
    let (messages, ending) = read_all(&cut);
    assert_eq!(
        ending,
        Ending::Truncated {
            length: (whole.len() / 2) as u64
        }
    );
    assert!(
        messages.len() > 1000 && messages.len() < 4000,
        "{}",
        messages.len()
    );
    // What was read is what was written, in order, up to the cut.
    let a: Vec<u64> = messages
        .iter()
        .filter(|m| m.channel.topic == "a/u64")
        .map(|m| postcard::from_bytes(&m.data).unwrap())
        .collect();
    assert_eq!(a, (0..a.len() as u64).collect::<Vec<_>>());
    let info = BagInfo::read(&cut).unwrap();
    assert!(!info.finished);
    assert!(
        info.ending_text().contains("truncated"),
        "{}",
        info.ending_text()
    );
    assert!(info.to_string().contains("unknown"), "{info}");
    // Garbage is damaged, not a panic.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"\x89MCAP0\r\nthis is not an mcap file at all").unwrap();
    let (messages, ending) = read_all(&junk);
    assert!(messages.is_empty());
    assert!(
        matches!(ending, Ending::Damaged { .. } | Ending::Truncated { .. }),
        "{ending:?}"
    );
    // A record claiming more than the reader accepts is refused, not allocated.
    let mut huge = whole[..8].to_vec();
    huge.push(0x01); // a header record
    huge.extend_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&junk, &huge).unwrap();
    let (_, ending) = read_all(&junk);
    assert!(matches!(ending, Ending::Damaged { .. }), "{ending:?}");
}

#[test]
fn a_channel_of_another_encoding_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ros.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = mcap::Writer::new(file).unwrap();
        let schema = writer
            .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
            .unwrap();
        let channel = writer
            .add_channel(schema, "/chatter", "cdr", &Default::default())
            .unwrap();
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: 1,
                    log_time: T0,
                    publish_time: T0,
                },
                b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00",
            )
            .unwrap();
        writer.finish().unwrap();
    }
    let (messages, ending) = read_all(&path);
    assert_eq!(ending, Ending::Complete);
    let err = messages[0].channel.playable(&path).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("channel 1 (/chatter)") && text.contains("ros2msg"),
        "{text}"
    );
    // bag info lists it with its encoding.
    let info = BagInfo::read(&path).unwrap();
    assert!(
        info.to_string().contains("schema encoding `ros2msg`"),
        "{info}"
    );
}

#[test]
fn filter_and_cut_keep_topics_and_time_ranges_with_their_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all.mcap");
    let mut writer = write_bag(&path, WriteOptions::default(), 500);
    writer.note_lost(
        "a/u64",
        Lost {
            gaps: 7,
            overflow: 0,
        },
    );
    writer.finish().unwrap();
    let only_a = dir.path().join("a.mcap");
    let done = rewrite(
        std::slice::from_ref(&path),
        &only_a,
        &Keep {
            topics: Some(vec!["a/u64".into()]),
            ..Keep::default()
        },
        WriteOptions::default(),
    )
    .unwrap();
    assert_eq!((done.read, done.kept), (1000, 500));
    let info = BagInfo::read(&only_a).unwrap();
    assert_eq!(info.topics.keys().collect::<Vec<_>>(), ["a/u64"]);
    assert_eq!(
        info.topics["a/u64"].lost.gaps, 7,
        "recorded losses go along"
    );
    let (messages, _) = read_all(&only_a);
    assert_eq!(messages[0].channel.meta, writer_meta(1), "QoS kept");

    // One second from 1 s after the start: samples 100..=200 of each topic.
    let cut = dir.path().join("cut.mcap");
    let done = rewrite(
        &[path],
        &cut,
        &Keep {
            from: Some(T0 + SECOND),
            to: Some(T0 + 2 * SECOND),
            ..Keep::default()
        },
        WriteOptions::default(),
    )
    .unwrap();
    assert_eq!(
        done.kept, 201,
        "100..=200 of a, 100..=199 of b (1 ns later)"
    );
    let (messages, _) = read_all(&cut);
    assert_eq!(messages.first().unwrap().log_time, T0 + SECOND);
}

#[test]
fn short_of_disk_space_the_file_is_finished_and_recording_stops() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("full.mcap");
    // A reserve larger than any disk: the first check stops it.
    let mut writer = BagWriter::create(
        &path,
        WriteOptions {
            reserve: u64::MAX,
            ..WriteOptions::default()
        },
    );
    // The check runs when the file opens: refused before anything is written.
    match writer.as_mut() {
        Err(BagError::DiskFull { free, .. }) => assert!(*free < u64::MAX),
        other => panic!("{other:?}"),
    }
    assert_eq!(read_all(&path).1, Ending::Complete, "a whole, empty file");
    // A reserve reached while writing: the write that passes it fails, the file is whole.
    let path = dir.path().join("later.mcap");
    let free = nix::sys::statvfs::statvfs(dir.path()).unwrap();
    #[allow(clippy::unnecessary_cast)]
    let free = free.blocks_available() as u64 * free.fragment_size() as u64;
    let mut writer = BagWriter::create(
        &path,
        WriteOptions {
            reserve: free.saturating_sub(3 << 20),
            compression: Compression::None,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    let channel = writer.add_channel(
        "big",
        &TypeDescription::of::<Vec<u8>>(),
        ChannelMeta::default(),
    );
    let blob = postcard::to_allocvec(&vec![7u8; 256 << 10]).unwrap();
    let mut written = 0;
    let stopped = loop {
        match writer.write(Record {
            channel,
            seq: written + 1,
            log_time: T0 + written,
            publish_time: T0,
            data: &blob,
        }) {
            Ok(()) => written += 1,
            Err(err) => break err,
        }
        assert!(written < 1000, "never stopped");
    };
    assert!(matches!(stopped, BagError::DiskFull { .. }), "{stopped}");
    assert!(stopped.to_string().contains("closed properly"), "{stopped}");
    let (messages, ending) = read_all(&path);
    assert_eq!(ending, Ending::Complete);
    assert_eq!(
        messages.len() as u64,
        written,
        "the refused write is not in"
    );
    assert!(matches!(
        writer.write(Record {
            channel,
            seq: 0,
            log_time: T0,
            publish_time: T0,
            data: &blob,
        }),
        Err(BagError::Finished)
    ));
}
