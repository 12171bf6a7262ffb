//! A small deterministic random generator (xorshift64): the same seed gives the same numbers
//! on every machine. Trainers draw their initial choices from it, so that a basis trained
//! from the same takes with the same seed is the same basis (its id is its content hash);
//! generated test motions use it so that tests are repeatable.

/// xorshift64; a zero seed is taken as 1 (xorshift's one fixed point).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_numbers() {
        let (mut a, mut b) = (Rng::new(7), Rng::new(7));
        let xs: Vec<u64> = (0..5).map(|_| a.next_u64()).collect();
        assert_eq!(xs, (0..5).map(|_| b.next_u64()).collect::<Vec<_>>());
        assert_ne!(
            Rng::new(0).next_u64(),
            0,
            "a zero seed does not stick at zero"
        );
        let u = Rng::new(3).unit();
        assert!((0.0..1.0).contains(&u));
    }
}
