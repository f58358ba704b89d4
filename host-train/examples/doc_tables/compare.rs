//! Whether a page's generated block still says what the code gives.

/// The firmware-budget columns whose figures are quantized by the bench's clock: `report.sh`
/// times each step with the SysTick at 168 MHz while QEMU's `-icount shift=0` runs one
/// instruction per ns, so one tick is 5.95 instructions. Where the tick boundaries fall depends on
/// how long the boot took, which moves with the code layout (the checkout's path, in panic
/// messages), so the worst and least steps read one tick apart between checkouts of one commit;
/// the traced instruction counts are identical.
const LAYOUT_JITTER_COLUMNS: [usize; 2] = [2, 3];
/// How far a figure of those columns may move (relative) and still match the page.
const LAYOUT_JITTER: f64 = 0.0025;

/// Whether a page's block says what the code gives: the same text, except that the
/// firmware-budget block's step figures may differ by [`LAYOUT_JITTER`].
pub fn same_block(name: &str, page: &str, code: &str) -> bool {
    if page == code {
        return true;
    }
    if name != "firmware-budget" || page.lines().count() != code.lines().count() {
        return false;
    }
    page.lines().zip(code.lines()).all(|(a, b)| {
        let (ca, cb): (Vec<&str>, Vec<&str>) = (a.split('|').collect(), b.split('|').collect());
        ca.len() == cb.len()
            && ca.iter().zip(&cb).enumerate().all(|(i, (x, y))| {
                x == y || (LAYOUT_JITTER_COLUMNS.contains(&i) && figures_close(x, y))
            })
    })
}

/// The same text around the numbers, and each pair of numbers within [`LAYOUT_JITTER`].
fn figures_close(a: &str, b: &str) -> bool {
    let split = |s: &str| -> (String, Vec<f64>) {
        let (mut text, mut nums, mut cur) = (String::new(), Vec::new(), String::new());
        for c in s.chars().chain(std::iter::once(' ')) {
            if c.is_ascii_digit() || (!cur.is_empty() && (c == ',' || c == '.')) {
                cur.push(c);
            } else {
                if !cur.is_empty() {
                    nums.push(
                        cur.replace(',', "")
                            .trim_end_matches('.')
                            .parse()
                            .unwrap_or(f64::NAN),
                    );
                    text.push('#');
                    cur.clear();
                }
                text.push(c);
            }
        }
        (text, nums)
    };
    let ((ta, na), (tb, nb)) = (split(a), split(b));
    ta == tb
        && na.len() == nb.len()
        && na
            .iter()
            .zip(&nb)
            .all(|(x, y)| (x - y).abs() <= LAYOUT_JITTER * x.abs().max(y.abs()))
}

#[cfg(test)]
mod tests {
    use super::same_block;

    const ROW: &str = "| composite law | 9,512 / 9,548 | 56.8 µs | 60,592 B | 888 / 1,016 B |\n";

    #[test]
    fn the_step_figures_may_move_with_the_layout_and_nothing_else() {
        let moved = ROW.replace("9,548", "9,542");
        assert!(same_block("firmware-budget", ROW, &moved));
        // Far beyond the layout's few instructions: a hand edit.
        assert!(!same_block(
            "firmware-budget",
            ROW,
            &ROW.replace("9,548", "9,648")
        ));
        // Every other column is exact.
        assert!(!same_block(
            "firmware-budget",
            ROW,
            &ROW.replace("60,592", "60,593")
        ));
        assert!(!same_block(
            "firmware-budget",
            ROW,
            &ROW.replace("µs", "ms")
        ));
        // Other blocks are exact.
        assert!(!same_block("bitcraze-summary", ROW, &moved));
    }
}
