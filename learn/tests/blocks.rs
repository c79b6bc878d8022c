//! Work split in blocks of items across threads: the results in the order of the items, whatever
//! the number of blocks.

use dynlab_learn::fit::in_n_blocks;

#[test]
fn blocks_cover_the_items_in_order_for_any_number_of_parts() {
    let items: Vec<u32> = (0..11).collect();
    let squares: Vec<u32> = items.iter().map(|x| x * x).collect();
    for parts in 0..=13 {
        let blocks = in_n_blocks(&items, parts, |b| {
            b.iter().map(|x| x * x).collect::<Vec<_>>()
        });
        assert!(blocks.len() <= parts.max(1), "{parts} parts: {blocks:?}");
        assert!(
            blocks.iter().all(|b| !b.is_empty()),
            "{parts} parts: {blocks:?}"
        );
        assert_eq!(blocks.concat(), squares, "{parts} parts");
    }
    let none: Vec<Vec<u32>> = in_n_blocks(&[], 4, |b: &[u32]| b.to_vec());
    assert_eq!(none, [Vec::<u32>::new()]);
}
