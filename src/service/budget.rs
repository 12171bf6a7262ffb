//! Memory the server holds for requests — bodies being read, answers being written — under
//! a total for the whole server and a share per caller.
//!
//! A limit per request does not bound a server (three 500 MB uploads at once held 2.7 GB),
//! and a total alone lets one caller hold all of it (two idle uploads declaring 512 MiB each
//! made every other write answer 503). So a [`Budget`] has both:
//! - a total: what every holder together may hold; past it a request is refused at once
//!   (503 with `Retry-After`), never queued in memory;
//! - a share per [`Holder`] (a token, or an address for requests without one): what one
//!   caller may hold across all its requests, so that others keep room. A caller holding
//!   nothing may still take one reservation larger than its share (one upload at the route's
//!   size limit always fits an idle server), never a second.
//!
//! A [`Reservation`] grows as its request really holds more (a body's bytes as they
//! arrive, not as declared) and gives everything back when dropped. Owners also count what
//! they actually hold ([`Reservation::hold`]): the gauges `/metrics` reports and the tests
//! check against what was reserved.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Budgets count in KiB so that one `u32` reservation covers anything a request may hold.
const UNIT: u64 = 1024;

/// Who holds a reservation: the unit a share is counted in.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Holder {
    /// A token, by id.
    Token(String),
    /// A caller without a token, by address.
    Address(IpAddr),
}

impl Holder {
    /// A caller without a token, by its address: an IPv6 client by its /64 (the block one
    /// client holds and can pick any address of), an IPv4 client by its address.
    pub fn address(ip: IpAddr) -> Holder {
        Holder::Address(match ip {
            IpAddr::V4(_) => ip,
            IpAddr::V6(a) => {
                let s = a.segments();
                IpAddr::from([s[0], s[1], s[2], s[3], 0, 0, 0, 0])
            }
        })
    }
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Holder::Token(id) => write!(f, "token {id}"),
            Holder::Address(a @ IpAddr::V6(_)) => write!(f, "address {a}/64"),
            Holder::Address(a) => write!(f, "address {a}"),
        }
    }
}

/// Why a reservation could not grow.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refused {
    /// The server holds its whole budget.
    Full { total: u64 },
    /// This holder holds its whole share.
    Share { share: u64 },
}

impl Refused {
    /// The reason, for a 503's message; `what` names what is held ("request bodies").
    pub fn reason(&self, what: &str) -> String {
        match self {
            Refused::Full { total } => format!(
                "the server holds as many {what} as its memory budget allows ({total} bytes)"
            ),
            Refused::Share { share } => format!(
                "this caller holds its whole share of the server's budget for {what} \
                 ({share} bytes); finish or cancel one first"
            ),
        }
    }
}

/// Bytes of one kind the server may hold at once; see the module doc.
pub struct Budget {
    permits: Arc<Semaphore>,
    total_units: u64,
    share_units: u64,
    /// Units reserved per holder, for the shares; holders with none are removed.
    by_holder: Mutex<HashMap<Holder, u64>>,
    /// Bytes really held now (what reservations' owners report), and the most ever.
    held: AtomicU64,
    held_peak: AtomicU64,
    /// The most one reservation's owner ever reported holding.
    one_peak: AtomicU64,
}

impl Budget {
    /// A budget of `total` bytes, of which one holder may hold `share`.
    pub fn new(total: u64, share: u64) -> Budget {
        let total_units = (total / UNIT).clamp(1, Semaphore::MAX_PERMITS as u64);
        Budget {
            permits: Arc::new(Semaphore::new(total_units as usize)),
            total_units,
            share_units: (share / UNIT).clamp(1, total_units),
            by_holder: Mutex::new(HashMap::new()),
            held: AtomicU64::new(0),
            held_peak: AtomicU64::new(0),
            one_peak: AtomicU64::new(0),
        }
    }

    /// The budget, bytes.
    pub fn total_bytes(&self) -> u64 {
        self.total_units * UNIT
    }

    /// One holder's share, bytes.
    pub fn share_bytes(&self) -> u64 {
        self.share_units * UNIT
    }

    /// Bytes reserved now (rounded up to KiB per reservation).
    pub fn reserved_bytes(&self) -> u64 {
        (self.total_units - self.permits.available_permits() as u64) * UNIT
    }

    /// Bytes reserved now by one holder.
    pub fn reserved_by(&self, holder: &Holder) -> u64 {
        self.by_holder
            .lock()
            .expect("budget lock")
            .get(holder)
            .copied()
            .unwrap_or(0)
            * UNIT
    }

    /// Bytes reservations' owners say they hold now; the most they ever held together; the
    /// most one ever held.
    pub fn held(&self) -> (u64, u64, u64) {
        (
            self.held.load(Ordering::Relaxed),
            self.held_peak.load(Ordering::Relaxed),
            self.one_peak.load(Ordering::Relaxed),
        )
    }

    /// An empty reservation for `holder`, to grow as its request holds more.
    pub fn reservation(self: &Arc<Self>, holder: Holder) -> Reservation {
        Reservation {
            budget: self.clone(),
            holder,
            units: 0,
            beside: 0,
            whole: false,
            permits: None,
            held: AtomicU64::new(0),
        }
    }

    /// An empty reservation for a part of a request that holds `parent` already (each take
    /// of a library export): the parent's units count as this one's for the rule that a
    /// caller alone may take one reservation past its share, so the part may be as large as
    /// a request of its own could be.
    pub fn reservation_beside(self: &Arc<Self>, parent: &Reservation) -> Reservation {
        let mut r = self.reservation(parent.holder.clone());
        r.beside = parent.units;
        r
    }

    fn add_held(&self, bytes: u64) {
        let now = self.held.fetch_add(bytes, Ordering::Relaxed) + bytes;
        self.held_peak.fetch_max(now, Ordering::Relaxed);
    }
}

/// What one request reserved from a [`Budget`]; given back when dropped (an answer's pieces
/// each keep it alive through their [`Held`] until the last is written).
pub struct Reservation {
    budget: Arc<Budget>,
    holder: Holder,
    units: u64,
    /// Units its request's parent reservation holds ([`Budget::reservation_beside`]).
    beside: u64,
    /// It asked for more than the whole budget and holds all of it (see
    /// [`Reservation::grow_to`]): what it holds may pass what it reserved.
    whole: bool,
    permits: Option<OwnedSemaphorePermit>,
    /// What its owner holds now (the sum of its live [`Held`]).
    held: AtomicU64,
}

impl Reservation {
    /// Bytes reserved.
    pub fn bytes(&self) -> u64 {
        self.units * UNIT
    }

    /// What this reservation's owner holds now.
    pub fn holding(&self) -> u64 {
        self.held.load(Ordering::Relaxed)
    }

    /// Reserve room for `bytes` in all (not more): refused at once when the server or this
    /// holder has not got it; a reservation never waits. A reservation larger than the
    /// whole budget takes the whole budget: it runs alone, or not at all.
    pub fn grow_to(&mut self, bytes: u64) -> Result<(), Refused> {
        let want = bytes.div_ceil(UNIT).min(self.budget.total_units);
        let whole = bytes.div_ceil(UNIT) > self.budget.total_units;
        if want <= self.units {
            self.whole |= whole;
            return Ok(());
        }
        let more = want - self.units;
        let b = &self.budget;
        let mut by = b.by_holder.lock().expect("budget lock");
        let mine = by.get(&self.holder).copied().unwrap_or(0);
        // Alone, a holder may take one reservation past its share; never a second.
        let alone = mine == self.units + self.beside;
        if !alone && mine + more > b.share_units {
            return Err(Refused::Share {
                share: b.share_bytes(),
            });
        }
        let full = Refused::Full {
            total: b.total_bytes(),
        };
        let n = u32::try_from(more).map_err(|_| full.clone())?;
        let p = b
            .permits
            .clone()
            .try_acquire_many_owned(n)
            .map_err(|_| full)?;
        match &mut self.permits {
            Some(held) => held.merge(p),
            None => self.permits = Some(p),
        }
        self.units = want;
        self.whole |= whole;
        by.insert(self.holder.clone(), mine + more);
        Ok(())
    }

    /// Count `bytes` as held by this reservation's owner (a buffer it allocated) until the
    /// guard is dropped: what the gauges report. Not a reservation: an owner keeps what it
    /// holds within what it reserved, and the tests check that it does.
    pub fn hold(self: &Arc<Self>, bytes: u64) -> Held {
        let now = self.held.fetch_add(bytes, Ordering::Relaxed) + bytes;
        debug_assert!(
            self.whole || now <= self.bytes(),
            "{} holds {now} bytes of the {} it reserved",
            self.holder,
            self.bytes()
        );
        self.budget.add_held(bytes);
        self.budget.one_peak.fetch_max(now, Ordering::Relaxed);
        Held {
            reservation: self.clone(),
            bytes,
        }
    }
}

impl Reservation {
    /// Bytes handed on to the connection that count as held (their capacity) until it has
    /// written them.
    pub fn hand_on(self: &Arc<Self>, data: Vec<u8>) -> bytes::Bytes {
        let held = self.hold(data.capacity() as u64);
        bytes::Bytes::from_owner(Piece { data, _held: held })
    }
}

/// A piece of output that counts as held until the connection has written it.
struct Piece {
    data: Vec<u8>,
    _held: Held,
}

impl AsRef<[u8]> for Piece {
    fn as_ref(&self) -> &[u8] {
        &self.data
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        if self.units == 0 {
            return;
        }
        let mut by = self.budget.by_holder.lock().expect("budget lock");
        if let Some(n) = by.get_mut(&self.holder) {
            *n = n.saturating_sub(self.units);
            if *n == 0 {
                by.remove(&self.holder);
            }
        }
        // The permits go back to the semaphore as `self.permits` drops.
    }
}

/// Bytes counted as held by a reservation's owner while this lives (see
/// [`Reservation::hold`]); it keeps the reservation alive.
pub struct Held {
    reservation: Arc<Reservation>,
    bytes: u64,
}

impl Drop for Held {
    fn drop(&mut self) {
        self.reservation
            .held
            .fetch_sub(self.bytes, Ordering::Relaxed);
        self.reservation
            .budget
            .held
            .fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

/// How many of something (open streams, watchers of a stream) each holder has, against a
/// most per holder: a caller cannot take every slot of a thing the server has few of.
#[derive(Debug)]
pub struct Shares {
    most: usize,
    by_holder: Arc<Mutex<HashMap<Holder, usize>>>,
}

impl Shares {
    /// At most `most` per holder.
    pub fn new(most: usize) -> Shares {
        Shares {
            most: most.max(1),
            by_holder: Arc::new(Mutex::new(HashMap::new())),
        }
    }

    /// The most one holder may have.
    pub fn most(&self) -> usize {
        self.most
    }

    /// One more for `holder`, given back when the returned guard drops; `None` when the
    /// holder has its most already.
    pub fn take(&self, holder: &Holder) -> Option<Share> {
        let mut by = self.by_holder.lock().expect("shares lock");
        let n = by.entry(holder.clone()).or_insert(0);
        if *n >= self.most {
            return None;
        }
        *n += 1;
        Some(Share {
            by_holder: self.by_holder.clone(),
            holder: holder.clone(),
        })
    }
}

/// One holder's one of a [`Shares`]; given back when dropped.
#[derive(Debug)]
pub struct Share {
    by_holder: Arc<Mutex<HashMap<Holder, usize>>>,
    holder: Holder,
}

impl Drop for Share {
    fn drop(&mut self) {
        let mut by = self.by_holder.lock().expect("shares lock");
        if let Some(n) = by.get_mut(&self.holder) {
            *n -= 1;
            if *n == 0 {
                by.remove(&self.holder);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn who(n: u8) -> Holder {
        Holder::Address(IpAddr::from([10, 0, 0, n]))
    }

    #[test]
    fn a_holder_keeps_within_its_share_and_the_server_within_its_total() {
        let b = Arc::new(Budget::new(100 * UNIT, 40 * UNIT));
        let mut a1 = b.reservation(who(1));
        a1.grow_to(30 * UNIT).unwrap();
        let mut a2 = b.reservation(who(1));
        assert_eq!(
            a2.grow_to(11 * UNIT),
            Err(Refused::Share { share: 40 * UNIT })
        );
        a2.grow_to(10 * UNIT).unwrap();
        assert_eq!(b.reserved_by(&who(1)), 40 * UNIT);
        // Others keep room.
        let mut c = b.reservation(who(2));
        c.grow_to(40 * UNIT).unwrap();
        let mut d = b.reservation(who(3));
        assert!(matches!(d.grow_to(21 * UNIT), Err(Refused::Full { .. })));
        d.grow_to(20 * UNIT).unwrap();
        drop((a1, a2));
        assert_eq!(b.reserved_by(&who(1)), 0);
        assert_eq!(b.reserved_bytes(), 60 * UNIT);
    }

    #[test]
    fn alone_a_holder_may_go_past_its_share_once() {
        let b = Arc::new(Budget::new(100 * UNIT, 40 * UNIT));
        let mut big = b.reservation(who(1));
        big.grow_to(70 * UNIT).unwrap();
        big.grow_to(90 * UNIT).unwrap();
        let mut second = b.reservation(who(1));
        assert!(matches!(second.grow_to(UNIT), Err(Refused::Share { .. })));
        drop(big);
        second.grow_to(UNIT).unwrap();
    }

    #[test]
    fn a_reservation_past_the_whole_budget_runs_alone() {
        let b = Arc::new(Budget::new(100 * UNIT, 40 * UNIT));
        let mut small = b.reservation(who(2));
        small.grow_to(UNIT).unwrap();
        let mut huge = b.reservation(who(1));
        assert!(matches!(
            huge.grow_to(500 * UNIT),
            Err(Refused::Full { .. })
        ));
        drop(small);
        huge.grow_to(500 * UNIT).unwrap();
        assert_eq!(b.reserved_bytes(), 100 * UNIT);
        let huge = Arc::new(huge);
        let _h = huge.hold(300 * UNIT); // it may hold more than the budget: it is alone
    }

    #[test]
    fn shares_cap_each_holder_and_come_back() {
        let s = Shares::new(2);
        let a = s.take(&who(1)).unwrap();
        let _b = s.take(&who(1)).unwrap();
        assert!(s.take(&who(1)).is_none());
        let _c = s.take(&who(2)).unwrap();
        drop(a);
        assert!(s.take(&who(1)).is_some());
    }

    #[test]
    fn what_is_held_is_tallied_and_given_back() {
        let b = Arc::new(Budget::new(100 * UNIT, 100 * UNIT));
        let mut r = b.reservation(who(1));
        r.grow_to(10 * UNIT).unwrap();
        let r = Arc::new(r);
        let x = r.hold(5000);
        let y = r.hold(4000);
        drop(x);
        let mut s = b.reservation(who(2));
        s.grow_to(3000).unwrap();
        let s = Arc::new(s);
        let z = s.hold(3000);
        assert_eq!(b.held(), (7000, 9000, 9000));
        assert_eq!(r.holding(), 4000);
        // A guard keeps its reservation (and so the budget's room) until it goes.
        drop(r);
        assert_eq!(b.reserved_bytes(), 13 * UNIT);
        drop((y, z, s));
        assert_eq!(b.held().0, 0);
        assert_eq!(b.reserved_bytes(), 0);
    }
}
