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

/// How many codes `members` (strictly ascending) take: one per member, plus a jump per 0xFFFF
/// in each gap.
pub fn code_count(members: &[u32]) -> usize {
    let mut prev = members.first().copied().unwrap_or(0);
    members
        .iter()
        .map(|&i| {
            let gap = i - prev;
            prev = i;
            1 + (gap / JUMP) as usize
        })
        .sum()
}

/// How many words `members` take: the first index's, then two codes to a word; none if empty.
pub fn word_count(members: &[u32]) -> usize {
    if members.is_empty() {
        0
    } else {
        1 + code_count(members).div_ceil(2)
    }
}

/// Appends `members` (strictly ascending) to `words`; returns (its first word, its code count).
/// An empty leaf takes no words.
pub fn encode(members: &[u32], words: &mut Vec<u32>) -> (usize, usize) {
    let begin = words.len();
    let Some(&first) = members.first() else {
        return (begin, 0);
    };
    words.push(first);
    let mut codes = 0;
    // The low half of a word whose high half is still to come.
    let mut low: Option<u32> = None;
    let mut put = |half: u32| {
        codes += 1;
        match low.take() {
            Some(l) => words.push(l | half << 16),
            None => low = Some(half),
        }
    };
    let mut prev = first;
    for &i in members {
        let mut gap = i - prev;
        while gap >= JUMP {
            put(JUMP);
            gap -= JUMP;
        }
        put(gap);
        prev = i;
    }
    if let Some(l) = low {
        words.push(l);
    }
    (begin, codes)
}

/// `members` coded on their own, in words of exactly the length they need: (the words, the
/// code count). What [`encode`] would append.
pub fn encode_leaf(members: &[u32]) -> (Vec<u32>, usize) {
    let mut words = Vec::with_capacity(word_count(members));
    let (_, codes) = encode(members, &mut words);
    (words, codes)
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
        // Counted without coding, and coded alone: the same codes and words.
        for (m, (&(begin, codes), &n)) in leaves.iter().zip(at.iter().zip(&appended)) {
            assert_eq!(code_count(m), codes);
            assert_eq!(word_count(m), n);
            let (alone, alone_codes) = encode_leaf(m);
            assert_eq!(alone_codes, codes);
            assert_eq!(alone.capacity(), n);
            assert_eq!(&alone[..], &words[begin..begin + n]);
        }
    }
}
