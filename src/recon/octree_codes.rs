//! Compact octree references (stage `octree_codes`; twin: `code_half` and the leaf loops in
//! `glsl/field/neighbours.glsl`): a leaf's sample indices, strictly ascending, as one 32-bit
//! word holding the first index, then 16-bit gaps from the previous index (the first gap 0),
//! two to a word. A gap of 0xFFFF or more is written as that many JUMP codes (each adds 0xFFFF
//! and names no sample) and the remainder. A node addresses its leaf by the word and counts its
//! codes, jumps included.
//!
//! Why: an index costs 4 bytes and a leaf lists every sample whose support reaches it, about
//! 100 references per sample for scattered points; 10⁶ points held 430 MB of indices. Gaps
//! within a leaf are small (its samples are neighbours, and a leaf holds a few hundred of n),
//! so a reference takes 2 bytes. Why jumps and not an escape followed by a full index: with
//! jumps every code sits at a fixed place (word + 1 + code number / 2), so a kernel computes
//! the next code's address without waiting for this one's value, and loads overlap as they did
//! with plain indices (an escape made each address depend on the last code read: the coherent
//! probe lost 20%).

/// The code that adds 0xFFFF to the running index and names no sample.
pub const JUMP: u32 = 0xFFFF;

/// Appends `members` (strictly ascending) to `words`; returns (its first word, its code count).
/// An empty leaf takes no words.
pub fn encode(members: &[u32], words: &mut Vec<u32>) -> (usize, usize) {
    let begin = words.len();
    let Some(&first) = members.first() else {
        return (begin, 0);
    };
    words.push(first);
    let mut halves: Vec<u32> = Vec::with_capacity(members.len() + 1);
    let mut prev = first;
    for &i in members {
        let mut gap = i - prev;
        while gap >= JUMP {
            halves.push(JUMP);
            gap -= JUMP;
        }
        halves.push(gap);
        prev = i;
    }
    let codes = halves.len();
    words.extend(
        halves
            .chunks(2)
            .map(|p| p[0] | p.get(1).map_or(0, |h| h << 16)),
    );
    (begin, codes)
}

/// The indices of one leaf: `codes` codes after the first index at word `begin` of `words`.
#[derive(Debug, Clone)]
pub struct LeafCodes<'a> {
    words: &'a [u32],
    half: usize,
    left: u32,
    prev: u32,
}

impl<'a> LeafCodes<'a> {
    pub fn new(words: &'a [u32], begin: u32, codes: u32) -> Self {
        Self {
            words,
            half: 2 * (begin as usize + 1),
            left: codes,
            prev: if codes == 0 {
                0
            } else {
                words.get(begin as usize).copied().unwrap_or(0)
            },
        }
    }

    /// An empty list.
    pub fn empty() -> Self {
        Self::new(&[], 0, 0)
    }

    fn next_half(&mut self) -> u32 {
        let word = self.words.get(self.half / 2).copied().unwrap_or(0);
        let shift = 16 * (self.half % 2);
        self.half += 1;
        (word >> shift) & 0xFFFF
    }
}

impl Iterator for LeafCodes<'_> {
    type Item = u32;

    fn next(&mut self) -> Option<u32> {
        while self.left > 0 {
            self.left -= 1;
            let code = self.next_half();
            self.prev = self.prev.wrapping_add(code);
            if code != JUMP {
                return Some(self.prev);
            }
        }
        None
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (0, Some(self.left as usize))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaves_decode_to_their_members_across_jumps_and_word_boundaries() {
        let leaves: Vec<Vec<u32>> = vec![
            vec![],
            vec![0],
            vec![7],
            vec![0, 1, 2, 3, 4],
            // Gaps at and around a jump, and indices past 16 bits.
            vec![
                3,
                0xFFFF + 2,
                0xFFFF + 3,
                0x1_FFFD,
                70_000_000,
                70_000_001,
                u32::MAX,
            ],
            vec![0xFFFE, 0xFFFE + 0xFFFE, 0xFFFE + 0xFFFE + 0xFFFF],
            (0..1000).map(|k| k * 97).collect(),
        ];
        let mut words = Vec::new();
        let mut at = Vec::new();
        let mut appended = Vec::new();
        for m in &leaves {
            let before = words.len();
            at.push(encode(m, &mut words));
            appended.push(words.len() - before);
        }
        for (m, &(begin, codes)) in leaves.iter().zip(&at) {
            let decoded: Vec<u32> = LeafCodes::new(&words, begin as u32, codes as u32).collect();
            assert_eq!(&decoded, m);
        }
        // Near indices take one half each: the first index's word, then 1000 codes in 500.
        assert_eq!(appended[6], 501);
        // Gaps 65534, 1, 65531 (one code each), 69 868 931 (1066 jumps + 1), 1, and
        // 4 224 967 294 (64 468 jumps + 1), after the first gap 0.
        assert_eq!(at[4].1, 1 + 1 + 1 + 1 + 1067 + 1 + 64_469);
        // The gap 0xFFFF itself is one jump and a 0.
        assert_eq!(at[5].1, 1 + 1 + 2);
    }
}
