//! Who an endpoint believes: only the peers discovery matched it with, sending from the
//! locator discovery gave for them.
//!
//! A consumer acts on samples, heartbeats and gaps only from matched producers, and a producer
//! on acknowledgements and repair requests only from matched consumers; everything else is
//! dropped and counted by reason. One race is allowed for: a producer may learn of a match
//! (and send) before its consumer does, so a sample from a sender not matched *yet* is held,
//! bounded in count and time, and handed on if the match arrives; otherwise it is dropped as
//! unmatched. Nothing held is acted on before the match.
//!
//! Like the other state machines here, [`Admission`] reads no clock: expiry is driven by
//! [`Admission::handle_timeout`] at [`Admission::poll_timeout`].

use std::collections::VecDeque;
use std::net::SocketAddrV4;
use std::time::{Duration, Instant};

use crate::wire::Guid;
use foldhash::HashMap;

/// What [`Admission::check`] says of a sender.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Matched, and sending from where discovery said: believe it.
    Matched,
    /// Matched, but this came from another address (forged, or a stale route).
    WrongAddress,
    /// Not matched (yet).
    Unmatched,
}

/// Limits of the samples held for senders not matched yet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdmissionConfig {
    /// At most this many samples held at once (the oldest goes first).
    pub max_held: usize,
    /// At most this many bytes held at once, as the caller counts them (the oldest go first).
    pub max_held_bytes: usize,
    /// A held sample whose sender is not matched within this is dropped.
    pub hold_for: Duration,
    /// A sender that was matched stays believed this long after discovery let it go (at
    /// its locator): what it sent before it left may still be on the way, overtaken by the
    /// news of its leaving.
    pub departed_grace: Duration,
}

impl Default for AdmissionConfig {
    fn default() -> Self {
        // A consumer's match normally follows its producer's within milliseconds (one
        // daemon tells both, or both daemons announce at once), while a producer that was
        // told first may already write at full speed: 1024 samples or 1 MiB covers such a
        // burst; two seconds cover a loaded machine. An attacker gains nothing from the
        // room: what is held is never acted on before a match.
        AdmissionConfig {
            max_held: 1024,
            max_held_bytes: 1 << 20,
            hold_for: Duration::from_secs(2),
            departed_grace: Duration::from_secs(2),
        }
    }
}

/// Counters of what was not believed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AdmissionStats {
    /// Dropped: from a sender never matched (including held samples that expired or were
    /// pushed out).
    pub unmatched: u64,
    /// Dropped: from a matched sender's id at another address.
    pub wrong_address: u64,
    /// Held samples handed on once their sender was matched.
    pub released: u64,
}

#[derive(Debug)]
struct Held<S> {
    sender: Guid,
    from: SocketAddrV4,
    until: Instant,
    bytes: usize,
    item: S,
}

/// The matched senders of one endpoint, and the samples held for senders not matched yet.
#[derive(Debug)]
pub struct Admission<S> {
    config: AdmissionConfig,
    matched: HashMap<Guid, SocketAddrV4>,
    /// Senders discovery let go, believed until the instant given (see `departed_grace`).
    departed: HashMap<Guid, (SocketAddrV4, Instant)>,
    held: VecDeque<Held<S>>,
    held_bytes: usize,
    stats: AdmissionStats,
}

impl<S> Admission<S> {
    /// Nobody matched yet.
    pub fn new(config: AdmissionConfig) -> Self {
        Admission {
            config,
            matched: HashMap::default(),
            departed: HashMap::default(),
            held: VecDeque::new(),
            held_bytes: 0,
            stats: AdmissionStats::default(),
        }
    }

    /// Counters.
    pub fn stats(&self) -> AdmissionStats {
        self.stats
    }

    /// How many matched senders there are.
    pub fn matched_len(&self) -> usize {
        self.matched.len()
    }

    /// The senders matched, and those let go but still believed for a moment.
    pub fn senders(&self) -> impl Iterator<Item = &Guid> {
        self.matched.keys().chain(self.departed.keys())
    }

    /// Whether `sender` is matched (at any address).
    pub fn is_matched(&self, sender: &Guid) -> bool {
        self.matched.contains_key(sender)
    }

    /// What to make of something `sender` sent from `from`. A locator with an unspecified
    /// address (a socket bound to 0.0.0.0) is matched by its port alone.
    pub fn check(&self, sender: &Guid, from: SocketAddrV4) -> Verdict {
        let known = self
            .matched
            .get(sender)
            .or_else(|| self.departed.get(sender).map(|(locator, _)| locator));
        match known {
            Some(locator) if same_place(*locator, from) => Verdict::Matched,
            Some(_) => Verdict::WrongAddress,
            None => Verdict::Unmatched,
        }
    }

    /// [`check`](Self::check), counting what is not believed (for what is dropped at once:
    /// heartbeats, gaps, feedback).
    pub fn admit(&mut self, sender: &Guid, from: SocketAddrV4) -> bool {
        let verdict = self.check(sender, from);
        self.count(verdict);
        verdict == Verdict::Matched
    }

    fn count(&mut self, verdict: Verdict) {
        match verdict {
            Verdict::Matched => {}
            Verdict::WrongAddress => self.stats.wrong_address += 1,
            Verdict::Unmatched => self.stats.unmatched += 1,
        }
    }

    /// Offers a sample of `bytes` bytes: `Some(item)` back when its sender is matched (to be
    /// acted on now); held (as `hold(item)`, say a copy that frees a shared buffer) when the
    /// sender is not matched yet; dropped (and counted) when it came from the wrong address.
    pub fn offer(
        &mut self,
        now: Instant,
        sender: Guid,
        from: SocketAddrV4,
        bytes: usize,
        item: S,
        hold: impl FnOnce(S) -> S,
    ) -> Option<S> {
        match self.check(&sender, from) {
            Verdict::Matched => Some(item),
            Verdict::WrongAddress => {
                self.stats.wrong_address += 1;
                None
            }
            Verdict::Unmatched => {
                if self.config.max_held == 0 || bytes > self.config.max_held_bytes {
                    self.stats.unmatched += 1;
                    return None;
                }
                while self.held.len() >= self.config.max_held
                    || self.held_bytes + bytes > self.config.max_held_bytes
                {
                    self.drop_oldest();
                }
                self.held_bytes += bytes;
                self.held.push_back(Held {
                    sender,
                    from,
                    until: now + self.config.hold_for,
                    bytes,
                    item: hold(item),
                });
                None
            }
        }
    }

    fn drop_oldest(&mut self) {
        if let Some(held) = self.held.pop_front() {
            self.held_bytes -= held.bytes;
            self.stats.unmatched += 1;
        }
    }

    /// Records a match: `sender` sends from `locator`. Returns the samples held for it that
    /// came from there, oldest first (those from elsewhere are dropped as wrong address).
    pub fn matched(&mut self, sender: Guid, locator: SocketAddrV4) -> Vec<S> {
        self.departed.remove(&sender);
        self.matched.insert(sender, locator);
        let mut released = Vec::new();
        let mut kept = VecDeque::with_capacity(self.held.len());
        for held in self.held.drain(..) {
            if held.sender != sender {
                kept.push_back(held);
                continue;
            }
            self.held_bytes -= held.bytes;
            if same_place(locator, held.from) {
                self.stats.released += 1;
                released.push(held.item);
            } else {
                self.stats.wrong_address += 1;
            }
        }
        self.held = kept;
        released
    }

    /// Forgets a match at `now` (the sender left, or discovery dropped it); it stays believed
    /// for the departed grace.
    pub fn unmatched(&mut self, now: Instant, sender: &Guid) {
        if let Some(locator) = self.matched.remove(sender) {
            self.departed
                .insert(*sender, (locator, now + self.config.departed_grace));
        }
    }

    /// Keeps exactly these matches; returns the samples released for senders that are new.
    pub fn set_matched(
        &mut self,
        now: Instant,
        senders: impl IntoIterator<Item = (Guid, SocketAddrV4)>,
    ) -> Vec<S> {
        let senders: HashMap<Guid, SocketAddrV4> = senders.into_iter().collect();
        let gone: Vec<Guid> = self
            .matched
            .keys()
            .filter(|guid| !senders.contains_key(guid))
            .copied()
            .collect();
        for guid in gone {
            self.unmatched(now, &guid);
        }
        let mut released = Vec::new();
        for (guid, locator) in senders {
            if self.matched.get(&guid) != Some(&locator) {
                released.extend(self.matched(guid, locator));
            }
        }
        released
    }

    /// Drops held samples whose time ran out, and forgets departed senders whose grace did.
    pub fn handle_timeout(&mut self, now: Instant) {
        while self.held.front().is_some_and(|held| held.until <= now) {
            self.drop_oldest();
        }
        self.departed.retain(|_, (_, until)| *until > now);
    }

    /// When a held sample or a departed sender's grace runs out next.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let departed = self.departed.values().map(|(_, until)| *until).min();
        match (self.held.front().map(|held| held.until), departed) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// Whether `from` is the place `locator` names (an unspecified address matches any address
/// with the same port).
fn same_place(locator: SocketAddrV4, from: SocketAddrV4) -> bool {
    locator.port() == from.port() && (locator.ip().is_unspecified() || locator.ip() == from.ip())
}

#[cfg(test)]
mod tests {
    use std::net::Ipv4Addr;

    use super::*;

    fn guid(n: u64) -> Guid {
        Guid {
            participant: n,
            entity: 1,
        }
    }

    fn at(port: u16) -> SocketAddrV4 {
        SocketAddrV4::new(Ipv4Addr::LOCALHOST, port)
    }

    #[test]
    fn only_a_matched_sender_at_its_locator_is_believed() {
        let t0 = Instant::now();
        let mut a = Admission::new(AdmissionConfig::default());
        assert!(a.matched(guid(1), at(7000)).is_empty());
        assert_eq!(a.offer(t0, guid(1), at(7000), 1, 'a', |x| x), Some('a'));
        assert_eq!(
            a.offer(t0, guid(1), at(7001), 1, 'b', |x| x),
            None,
            "another port"
        );
        let elsewhere = SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 9), 7000);
        assert!(!a.admit(&guid(1), elsewhere), "another host");
        assert!(!a.admit(&guid(2), at(7000)), "never matched");
        assert_eq!(
            a.stats(),
            AdmissionStats {
                unmatched: 1,
                wrong_address: 2,
                released: 0
            }
        );
        a.unmatched(t0, &guid(1));
        assert_eq!(
            a.check(&guid(1), at(7000)),
            Verdict::Matched,
            "still on the way when it left"
        );
        a.handle_timeout(t0 + Duration::from_secs(2));
        assert_eq!(a.check(&guid(1), at(7000)), Verdict::Unmatched);
    }

    #[test]
    fn samples_before_the_match_are_held_and_handed_on_in_order() {
        let t0 = Instant::now();
        let mut a = Admission::new(AdmissionConfig::default());
        assert_eq!(a.offer(t0, guid(1), at(7000), 8, 1, |x| x), None);
        assert_eq!(a.offer(t0, guid(2), at(7100), 8, 9, |x| x), None);
        assert_eq!(a.offer(t0, guid(1), at(7000), 8, 2, |x| x), None);
        assert_eq!(
            a.offer(t0, guid(1), at(6666), 8, 3, |x| x),
            None,
            "a forger's, held too"
        );
        assert_eq!(a.matched(guid(1), at(7000)), vec![1, 2]);
        assert_eq!(
            a.stats().wrong_address,
            1,
            "the forged one is dropped at the match"
        );
        assert_eq!(a.stats().released, 2);
        // The other sender's sample runs out.
        assert_eq!(a.poll_timeout(), Some(t0 + Duration::from_secs(2)));
        a.handle_timeout(t0 + Duration::from_secs(2));
        assert_eq!(a.poll_timeout(), None);
        assert_eq!(a.stats().unmatched, 1);
        assert!(a.matched(guid(2), at(7100)).is_empty());
    }

    #[test]
    fn a_flood_from_unmatched_senders_holds_a_bounded_number() {
        let t0 = Instant::now();
        let config = AdmissionConfig::default();
        let mut a = Admission::new(config);
        for n in 0..10_000_u64 {
            a.offer(t0, guid(100 + n), at(9000), 8, n, |x| x);
        }
        assert_eq!(a.held.len(), config.max_held);
        assert_eq!(a.stats().unmatched, 10_000 - config.max_held as u64);
        // And by bytes: large samples push the small ones out.
        for n in 0..100_u64 {
            a.offer(t0, guid(50_000 + n), at(9000), 256 * 1024, n, |x| x);
        }
        assert!(a.held_bytes <= config.max_held_bytes);
        assert_eq!(a.held.len(), 4);
        assert_eq!(
            a.offer(t0, guid(1), at(9000), 2 << 20, 0, |x| x),
            None,
            "never held whole"
        );
        assert_eq!(a.held.len(), 4);
    }

    #[test]
    fn set_matched_keeps_the_given_senders_and_releases_for_new_ones() {
        let t0 = Instant::now();
        let mut a = Admission::new(AdmissionConfig::default());
        a.matched(guid(1), at(7000));
        a.offer(t0, guid(2), at(7200), 1, 'x', |x| x);
        let released = a.set_matched(t0, [(guid(2), at(7200))]);
        assert_eq!(released, vec!['x']);
        assert!(!a.is_matched(&guid(1)));
        assert_eq!(a.matched_len(), 1);
        assert_eq!(a.poll_timeout(), Some(t0 + Duration::from_secs(1) * 2));
    }

    #[test]
    fn an_unspecified_locator_matches_by_port() {
        let mut a = Admission::<()>::new(AdmissionConfig::default());
        a.matched(guid(1), SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, 7000));
        assert!(a.admit(&guid(1), at(7000)));
        assert!(!a.admit(&guid(1), at(7001)));
    }
}
