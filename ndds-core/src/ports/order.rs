//! A module's `order` (Shin, 1985, section 5, after Silberschatz's CELL): which of its sections
//! may interrupt which, so that a query is answered only when nothing more urgent runs.
//!
//! An [`Order`] ranks a module's *sections*: its background code (named by the module's own
//! name), its response handlers (`PORT.RESPONSE`), its exception handlers (`PORT.TIMEOUT`) and
//! its named subprograms. The first is the most urgent. Sections the order does not name rank
//! below every named one, as ports without a priority rank below every declared one.
//!
//! [`Sections`] applies it. Rust code cannot be interrupted anywhere, so a module yields at
//! *preemption points*: the entry and exit of a named section, every blocking port primitive
//! while it waits, and wherever the module calls [`Sections::next_at_point`] itself. A handler
//! whose event is pending (a query arrived, a timeout expired) runs at such a point when it
//! outranks the *innermost* running section — the one the module is in now, not the ones that
//! called it. With nothing running, the most urgent pending handler runs; equals run in the
//! order their events arrived.
//!
//! CHIP_IT in the paper's appendix shows why the innermost section counts: its order is
//! `(READY_TO_CHIP.TIMEOUT, SHARE_FEEDER.TIMEOUT, CHIP_IT, GRASP, SHARE_FEEDER1.CRIT_SECTION,
//! INSERT)`. The background code calls GRASP and INSERT through its work schedule; a query
//! from CHIP_IT2 for the critical section must wait while the background code or GRASP runs,
//! and be answered while INSERT runs, below which it ranks.

use std::collections::BTreeMap;
use std::fmt;

/// Events waiting for their handlers, at most, by default.
pub const DEFAULT_CAPACITY: usize = 1024;

/// A problem with an order, and where it is when it was read from text.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OrderError {
    /// A section named twice.
    #[error("{at}`{0}` is named twice in the order", at = At(.1))]
    Duplicate(String, Option<(usize, usize)>),
    /// A name that is no section of the module (not its name, a handler or a subprogram).
    #[error(
        "`{0}` in the order is no section of module `{1}` (its name, a handler or a subprogram)"
    )]
    Unknown(String, String),
    /// Text that does not read as an order.
    #[error("line {line}, column {column}: {what}")]
    Syntax {
        /// From 1.
        line: usize,
        /// From 1, in characters.
        column: usize,
        /// What was expected or found.
        what: String,
    },
    /// A section left that is not the innermost one running.
    #[error("left section `{left}` while `{innermost}` runs inside it")]
    NotInnermost {
        /// The section left.
        left: String,
        /// The section still running inside it (empty if none runs).
        innermost: String,
    },
}

struct At<'a>(&'a Option<(usize, usize)>);

impl fmt::Display for At<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some((line, column)) => write!(f, "line {line}, column {column}: "),
            None => Ok(()),
        }
    }
}

/// A module's sections, most urgent first.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Order {
    names: Vec<String>,
}

/// Where a section stands: its place in the order (0 the most urgent), or [`Rank::UNNAMED`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Rank(pub u32);

impl Rank {
    /// A section the order does not name: below every named one.
    pub const UNNAMED: Rank = Rank(u32::MAX);
}

impl Order {
    /// The order of these sections, most urgent first; a name given twice is refused.
    pub fn new<S: Into<String>>(names: impl IntoIterator<Item = S>) -> Result<Order, OrderError> {
        let mut order = Order::default();
        for name in names {
            let name = name.into();
            if order.names.contains(&name) {
                return Err(OrderError::Duplicate(name, None));
            }
            order.names.push(name);
        }
        Ok(order)
    }

    /// Reads an order as the paper writes it — `ORDER(A.TIMEOUT, B, C.RESPONSE, D);`, over
    /// several lines if need be, with `--` or `#` comments — or just the list, with `,` or `;`
    /// between the names (a `;` after the last name ends the order). `ORDER()` is the empty
    /// order, as an empty order displays itself.
    pub fn parse(text: &str) -> Result<Order, OrderError> {
        let tokens = tokenize(text)?;
        let mut at = 0;
        let eat = |at: &mut usize, what: &str| {
            if tokens.get(*at).is_some_and(|t| t.text == what) {
                *at += 1;
                true
            } else {
                false
            }
        };
        if tokens
            .get(at)
            .is_some_and(|t| t.text.eq_ignore_ascii_case("order"))
            && tokens.get(at + 1).is_some_and(|t| t.text == "(")
        {
            at += 1;
        }
        let parenthesized = eat(&mut at, "(");
        let mut order = Order::default();
        if parenthesized && tokens.get(at).is_some_and(|t| t.text == ")") {
            at += 1;
            eat(&mut at, ";");
            if at < tokens.len() {
                return Err(syntax(&tokens, at, "the end of the order"));
            }
            return Ok(order);
        }
        loop {
            let Some(token) = tokens.get(at).filter(|t| t.is_name()) else {
                return Err(syntax(&tokens, at, "a section name"));
            };
            if order.names.contains(&token.text) {
                return Err(OrderError::Duplicate(
                    token.text.clone(),
                    Some((token.line, token.column)),
                ));
            }
            order.names.push(token.text.clone());
            at += 1;
            if eat(&mut at, ",") {
                continue;
            }
            // `;` separates names; in a bare list, one that no name follows ends the order.
            if tokens.get(at).is_some_and(|t| t.text == ";")
                && (parenthesized || tokens.get(at + 1).is_some_and(Token::is_name))
            {
                at += 1;
                continue;
            }
            break;
        }
        if parenthesized && !eat(&mut at, ")") {
            return Err(syntax(&tokens, at, "`,` or `)`"));
        }
        eat(&mut at, ";");
        if at < tokens.len() {
            return Err(syntax(&tokens, at, "the end of the order"));
        }
        Ok(order)
    }

    /// The sections, most urgent first.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The rank of `section`.
    pub fn rank(&self, section: &str) -> Rank {
        self.names
            .iter()
            .position(|n| n == section)
            .map_or(Rank::UNNAMED, |i| Rank(i as u32))
    }

    /// Checks, for module `module`, that the order names only its sections: `module` itself
    /// (the background code) or one of `sections`. Every unknown name is reported at once.
    pub fn check<'a>(
        &self,
        module: &str,
        sections: impl IntoIterator<Item = &'a str> + Clone,
    ) -> Result<(), Vec<OrderError>> {
        let unknown: Vec<OrderError> = self
            .names
            .iter()
            .filter(|n| *n != module && !sections.clone().into_iter().any(|s| s == *n))
            .map(|n| OrderError::Unknown(n.clone(), module.to_string()))
            .collect();
        if unknown.is_empty() {
            Ok(())
        } else {
            Err(unknown)
        }
    }
}

impl fmt::Display for Order {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ORDER({})", self.names.join(", "))
    }
}

struct Token {
    text: String,
    line: usize,
    column: usize,
}

impl Token {
    fn is_name(&self) -> bool {
        self.text
            .chars()
            .next()
            .is_some_and(|c| c.is_alphabetic() || c == '_')
    }
}

fn tokenize(text: &str) -> Result<Vec<Token>, OrderError> {
    let mut tokens = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let mut chars = line.chars().enumerate().peekable();
        while let Some((column, c)) = chars.next() {
            let token = |text: String| Token {
                text,
                line: index + 1,
                column: column + 1,
            };
            match c {
                '#' => break,
                '-' if chars.peek().is_some_and(|(_, n)| *n == '-') => break,
                '(' | ')' | ',' | ';' => tokens.push(token(c.to_string())),
                c if c.is_whitespace() => {}
                c if c.is_alphanumeric() || c == '_' => {
                    let mut name = c.to_string();
                    while let Some((_, n)) = chars
                        .peek()
                        .filter(|(_, n)| n.is_alphanumeric() || matches!(n, '_' | '.'))
                    {
                        name.push(*n);
                        chars.next();
                    }
                    tokens.push(token(name));
                }
                other => {
                    return Err(OrderError::Syntax {
                        line: index + 1,
                        column: column + 1,
                        what: format!("`{other}` cannot be part of an order"),
                    });
                }
            }
        }
    }
    Ok(tokens)
}

fn syntax(tokens: &[Token], at: usize, wanted: &str) -> OrderError {
    match tokens.get(at) {
        Some(token) => OrderError::Syntax {
            line: token.line,
            column: token.column,
            what: format!("expected {wanted}, found `{}`", token.text),
        },
        None => {
            let (line, column) = tokens
                .last()
                .map_or((1, 1), |t| (t.line, t.column + t.text.chars().count()));
            OrderError::Syntax {
                line,
                column,
                what: format!("expected {wanted}, found the end"),
            }
        }
    }
}

/// The sections of one module running now, and the events waiting for their handlers.
pub struct Sections<E> {
    order: Order,
    running: Vec<(String, Rank)>,
    pending: BTreeMap<(Rank, u64), (String, E)>,
    arrivals: u64,
    capacity: usize,
}

/// An event refused because [`Sections`] holds its capacity already; the event comes back.
#[derive(Clone, PartialEq, Eq, thiserror::Error)]
#[error("{count} events already wait for handlers; `{handler}` refused")]
pub struct Overflow<E> {
    /// The handler it was for.
    pub handler: String,
    /// How many wait.
    pub count: usize,
    /// The event.
    pub event: E,
}

impl<E> fmt::Debug for Overflow<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Overflow")
            .field("handler", &self.handler)
            .field("count", &self.count)
            .finish_non_exhaustive()
    }
}

impl<E> Sections<E> {
    /// Nothing running and nothing pending, under `order`, holding at most
    /// [`DEFAULT_CAPACITY`] pending events.
    pub fn new(order: Order) -> Self {
        Self::with_capacity(order, DEFAULT_CAPACITY)
    }

    /// The same, holding at most `capacity` pending events.
    pub fn with_capacity(order: Order, capacity: usize) -> Self {
        Sections {
            order,
            running: Vec::new(),
            pending: BTreeMap::new(),
            arrivals: 0,
            capacity,
        }
    }

    /// The order applied.
    pub fn order(&self) -> &Order {
        &self.order
    }

    /// The module enters `section` (its background code, a subprogram, or a handler it was
    /// given by [`Sections::next_at_point`]), inside whatever runs now.
    pub fn enter(&mut self, section: &str) {
        let rank = self.order.rank(section);
        self.running.push((section.to_string(), rank));
    }

    /// The module leaves `section`, which must be the innermost one running.
    pub fn leave(&mut self, section: &str) -> Result<(), OrderError> {
        match self.running.last() {
            Some((name, _)) if name == section => {
                self.running.pop();
                Ok(())
            }
            other => Err(OrderError::NotInnermost {
                left: section.to_string(),
                innermost: other.map(|(n, _)| n.clone()).unwrap_or_default(),
            }),
        }
    }

    /// The innermost section running, if any.
    pub fn innermost(&self) -> Option<&str> {
        self.running.last().map(|(n, _)| n.as_str())
    }

    /// An event for `handler` (a query for a response handler, an expired timeout for an
    /// exception handler) waits until a preemption point lets it run.
    pub fn post(&mut self, handler: &str, event: E) -> Result<(), Overflow<E>> {
        if self.pending.len() >= self.capacity {
            return Err(Overflow {
                handler: handler.to_string(),
                count: self.pending.len(),
                event,
            });
        }
        let rank = self.order.rank(handler);
        self.arrivals += 1;
        self.pending
            .insert((rank, self.arrivals), (handler.to_string(), event));
        Ok(())
    }

    /// How many events wait.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// At a preemption point: the pending event whose handler may run now (it outranks the
    /// innermost running section, or nothing runs), the most urgent first, taken out. The
    /// caller runs the handler between `enter(handler)` and `leave(handler)`.
    pub fn next_at_point(&mut self) -> Option<(String, E)> {
        let (&(rank, _), _) = self.pending.first_key_value()?;
        let may = match self.running.last() {
            None => true,
            Some((_, innermost)) => rank < *innermost,
        };
        if !may {
            return None;
        }
        self.pending
            .pop_first()
            .map(|(_, handler_event)| handler_event)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHIP_IT: &str = "\
ORDER(READY_TO_CHIP.TIMEOUT,
      SHARE_FEEDER.TIMEOUT,
      CHIP_IT,
      GRASP,
      -- A subprogram whose code is omitted.
SHARE_FEEDER1.CRIT_SECTION,
INSERT);                        -- inserts a chip at X,Y,Z.
";

    #[test]
    fn the_papers_order_reads_as_written() {
        let order = Order::parse(CHIP_IT).unwrap();
        assert_eq!(
            order.names(),
            [
                "READY_TO_CHIP.TIMEOUT",
                "SHARE_FEEDER.TIMEOUT",
                "CHIP_IT",
                "GRASP",
                "SHARE_FEEDER1.CRIT_SECTION",
                "INSERT"
            ]
        );
        assert_eq!(order.rank("CHIP_IT"), Rank(2));
        assert_eq!(order.rank("REPORT"), Rank::UNNAMED);
        assert_eq!(Order::parse(&order.to_string()).unwrap(), order);
        // The grammar's `;` between names, and a bare list.
        assert_eq!(Order::parse("(A; B; C)").unwrap().names(), ["A", "B", "C"]);
        assert_eq!(Order::parse("A, B").unwrap().names(), ["A", "B"]);
        assert_eq!(Order::parse("A; B").unwrap().names(), ["A", "B"]);
        assert_eq!(Order::parse("A; B;").unwrap().names(), ["A", "B"]);
        assert_eq!(Order::parse("A, B;").unwrap().names(), ["A", "B"]);
        assert!(Order::parse("A; B; ;").is_err());
        // The empty order reads back as it displays.
        let empty = Order::default();
        assert_eq!(empty.to_string(), "ORDER()");
        assert_eq!(Order::parse(&empty.to_string()).unwrap(), empty);
        assert_eq!(Order::parse("();").unwrap(), empty);
        assert!(Order::parse("ORDER() B").is_err());
        assert!(Order::parse("").is_err());
    }

    #[test]
    fn chip_its_order_answers_the_critical_section_query_only_during_insert() {
        let order = Order::parse(CHIP_IT).unwrap();
        order
            .check(
                "CHIP_IT",
                [
                    "READY_TO_CHIP.TIMEOUT",
                    "SHARE_FEEDER.TIMEOUT",
                    "SHARE_FEEDER1.CRIT_SECTION",
                    "GRASP",
                    "INSERT",
                ],
            )
            .unwrap();
        let mut sections = Sections::new(order);
        let query = "SHARE_FEEDER1.CRIT_SECTION";
        // CHIP_IT2 asks while the background code runs: it waits.
        sections.enter("CHIP_IT");
        sections.post(query, "from CHIP_IT2").unwrap();
        assert_eq!(sections.next_at_point(), None);
        // Nor during GRASP, the critical region.
        sections.enter("GRASP");
        assert_eq!(sections.next_at_point(), None);
        sections.leave("GRASP").unwrap();
        assert_eq!(
            sections.next_at_point(),
            None,
            "back in the background code"
        );
        // INSERT ranks below it: at INSERT's first preemption point the query is answered.
        sections.enter("INSERT");
        assert_eq!(
            sections.next_at_point(),
            Some((query.to_string(), "from CHIP_IT2"))
        );
        sections.enter(query);
        // While the answer runs, a timeout still preempts it.
        sections.post("SHARE_FEEDER.TIMEOUT", "3 s").unwrap();
        assert_eq!(
            sections.next_at_point(),
            Some(("SHARE_FEEDER.TIMEOUT".to_string(), "3 s"))
        );
        sections.leave(query).unwrap();
        sections.leave("INSERT").unwrap();
        // A timeout preempts the background code and GRASP too.
        sections.enter("GRASP");
        sections.post("READY_TO_CHIP.TIMEOUT", "60 s").unwrap();
        assert_eq!(
            sections.next_at_point().map(|(h, _)| h),
            Some("READY_TO_CHIP.TIMEOUT".to_string())
        );
        assert_eq!(sections.innermost(), Some("GRASP"));
    }

    #[test]
    fn with_nothing_running_the_most_urgent_goes_first_and_equals_in_arrival_order() {
        let order = Order::new(["T.TIMEOUT", "P.Q"]).unwrap();
        let mut sections = Sections::new(order);
        sections.post("P.Q", 1).unwrap();
        sections.post("OTHER.R", 2).unwrap(); // unnamed: last
        sections.post("P.Q", 3).unwrap();
        sections.post("T.TIMEOUT", 4).unwrap();
        let mut ran = Vec::new();
        while let Some((_, event)) = sections.next_at_point() {
            ran.push(event);
        }
        assert_eq!(ran, [4, 1, 3, 2]);
    }

    #[test]
    fn unnamed_sections_rank_below_every_named_one_and_do_not_preempt_each_other() {
        let order = Order::new(["M", "P.Q"]).unwrap();
        let mut sections = Sections::new(order);
        sections.enter("helper"); // not in the order
        sections.post("other.R", ()).unwrap(); // not in the order either
        assert_eq!(sections.next_at_point(), None, "equal ranks never preempt");
        sections.post("P.Q", ()).unwrap();
        assert_eq!(sections.next_at_point().map(|(h, _)| h), Some("P.Q".into()));
        sections.leave("helper").unwrap();
        assert_eq!(
            sections.next_at_point().map(|(h, _)| h),
            Some("other.R".into())
        );
    }

    #[test]
    fn leaving_a_section_that_is_not_the_innermost_is_refused() {
        let mut sections: Sections<()> = Sections::new(Order::default());
        sections.enter("A");
        sections.enter("B");
        assert_eq!(
            sections.leave("A"),
            Err(OrderError::NotInnermost {
                left: "A".into(),
                innermost: "B".into()
            })
        );
        assert_eq!(sections.innermost(), Some("B"));
    }

    #[test]
    fn pending_events_are_bounded() {
        let mut sections = Sections::with_capacity(Order::default(), 2);
        sections.post("a", 1).unwrap();
        sections.post("a", 2).unwrap();
        let refused = sections.post("b", 3).unwrap_err();
        assert_eq!(
            (refused.handler.as_str(), refused.count, refused.event),
            ("b", 2, 3)
        );
        assert_eq!(sections.pending(), 2);
    }

    #[test]
    fn every_unknown_name_is_reported_at_once() {
        let order = Order::parse("ORDER(CHIP_IT, GRASP, PRAY, WAIT.TIMEOUT)").unwrap();
        let errors = order.check("CHIP_IT", ["GRASP", "INSERT"]).unwrap_err();
        assert_eq!(
            errors,
            [
                OrderError::Unknown("PRAY".into(), "CHIP_IT".into()),
                OrderError::Unknown("WAIT.TIMEOUT".into(), "CHIP_IT".into())
            ]
        );
        assert!(
            errors[0]
                .to_string()
                .contains("no section of module `CHIP_IT`")
        );
    }

    #[test]
    fn mistakes_in_the_text_are_named_with_their_place() {
        let cases: &[(&str, &str)] = &[
            (
                "ORDER(A, B",
                "line 1, column 11: expected `,` or `)`, found the end",
            ),
            (
                "ORDER(A,, B)",
                "line 1, column 9: expected a section name, found `,`",
            ),
            (
                "ORDER(A, B) C",
                "line 1, column 13: expected the end of the order, found `C`",
            ),
            (
                "ORDER(A,\n  A)",
                "line 2, column 3: `A` is named twice in the order",
            ),
            (
                "ORDER(A, B*)",
                "line 1, column 11: `*` cannot be part of an order",
            ),
            (
                "",
                "line 1, column 1: expected a section name, found the end",
            ),
            (
                "ORDER(1A)",
                "line 1, column 7: expected a section name, found `1A`",
            ),
        ];
        for (text, message) in cases {
            assert_eq!(
                Order::parse(text).unwrap_err().to_string(),
                *message,
                "{text}"
            );
        }
        assert_eq!(
            Order::new(["A", "A"]).unwrap_err().to_string(),
            "`A` is named twice in the order"
        );
    }

    proptest::proptest! {
        #[test]
        fn no_text_panics_the_reader(text in "\\PC{0,200}") {
            let _ = Order::parse(&text);
        }

        #[test]
        fn every_order_reads_back_as_it_displays(
            names in proptest::collection::btree_set("[A-Z][A-Z0-9_]{0,6}(\\.[A-Z]{1,8})?", 0..8)
        ) {
            let order = Order::new(names).unwrap();
            proptest::prop_assert_eq!(Order::parse(&order.to_string()).unwrap(), order);
        }
    }
}
