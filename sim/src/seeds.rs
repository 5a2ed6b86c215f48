//! Seeded random streams: every draw of the simulator comes from a
//! [`rand::rngs::Xoshiro256PlusPlus`] seeded with [`derive_seed`]`(seed, stream, index)` (see
//! [`crate::campaign`] for the streams and why). Re-exported by [`crate::campaign`].

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;

/// Stream id of the random pose draws (index: pose).
pub const STREAM_POSES: u64 = 1;
/// Stream id of the random approach directions (index: pose).
pub const STREAM_DIRECTIONS: u64 = 2;
/// Stream id of the payload choices (index: pose).
pub const STREAM_PAYLOAD: u64 = 3;
/// Stream id of the tracker noise (index: row).
pub const STREAM_TRACKER: u64 = 4;
/// Stream id of the scenario's parameter draws (index: a hash of the key).
pub const STREAM_PARAMETERS: u64 = 5;
/// Stream id of the branch joints' values (index: pose).
pub const STREAM_BRANCHES: u64 = 6;

/// SplitMix64 finaliser: a bijective, well-mixing map of 64-bit words (Steele, Lea and Flood 2014).
#[inline]
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of item `index` of stream `stream` under the campaign seed `seed`.
#[inline]
pub fn derive_seed(seed: u64, stream: u64, index: u64) -> u64 {
    splitmix64(splitmix64(splitmix64(seed) ^ stream) ^ index)
}

/// A generator for item `index` of stream `stream` (see the module docs).
#[inline]
pub fn rng_for(seed: u64, stream: u64, index: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(derive_seed(seed, stream, index))
}
