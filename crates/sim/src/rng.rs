//! Seeded random streams. Each purpose (terrain, each rover's sensors, ...) gets its own
//! ChaCha8 stream derived from the one scenario seed, so adding a rover or a sensor does not
//! change the terrain or any other rover's noise.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The generator every random draw in the simulation comes from.
pub type SimRng = ChaCha8Rng;

/// Derives independent streams from the scenario seed.
#[derive(Clone, Copy, Debug)]
pub struct Streams {
    seed: u64,
}

/// What a stream is for; its number selects the ChaCha stream.
#[derive(Clone, Copy, Debug)]
pub enum Purpose {
    /// Terrain generation.
    Terrain,
    /// A rover's lidar noise.
    Lidar(u8),
    /// A rover's depth camera noise.
    Depth(u8),
    /// A rover's odometry and slip noise.
    Odometry(u8),
    /// A rover's gyro noise.
    Gyro(u8),
    /// A node's own decisions (e.g. a wandering behaviour).
    Node(u8),
}

impl Streams {
    /// Streams for a scenario seed.
    pub fn new(seed: u64) -> Self {
        Streams { seed }
    }

    /// The stream for one purpose.
    pub fn rng(&self, purpose: Purpose) -> SimRng {
        let stream = match purpose {
            Purpose::Terrain => 1,
            Purpose::Lidar(r) => 0x100 + r as u64,
            Purpose::Depth(r) => 0x200 + r as u64,
            Purpose::Odometry(r) => 0x300 + r as u64,
            Purpose::Gyro(r) => 0x400 + r as u64,
            Purpose::Node(r) => 0x500 + r as u64,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(stream);
        rng
    }
}
