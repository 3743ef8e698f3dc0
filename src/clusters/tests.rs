use super::*;
use proptest::prelude::*;

/// Small deterministic generator for test masks (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn random_mask(ny: usize, nx: usize, p: f64, seed: u64) -> Vec<bool> {
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    (0..ny * nx).map(|_| rng.unit() < p).collect()
}

/// Breadth-first reference labelling, clusters numbered in raster order of first cell.
fn bfs_labels(
    free: &[bool],
    ny: usize,
    nx: usize,
    conn: Connectivity,
    per: Periodic,
) -> (Vec<u32>, usize) {
    let mut lab = vec![0u32; ny * nx];
    let mut k = 0u32;
    let mut offs = vec![(-1i64, 0i64), (1, 0), (0, -1), (0, 1)];
    if conn == Connectivity::Eight {
        offs.extend([(-1, -1), (-1, 1), (1, -1), (1, 1)]);
    }
    let mut stack = Vec::new();
    for start in 0..ny * nx {
        if !free[start] || lab[start] != 0 {
            continue;
        }
        k += 1;
        lab[start] = k;
        stack.push(start);
        while let Some(c) = stack.pop() {
            let (i, j) = ((c / nx) as i64, (c % nx) as i64);
            for &(di, dj) in &offs {
                let (mut a, mut b) = (i + di, j + dj);
                if per.axis0 {
                    a = a.rem_euclid(ny as i64);
                }
                if per.axis1 {
                    b = b.rem_euclid(nx as i64);
                }
                if a < 0 || b < 0 || a >= ny as i64 || b >= nx as i64 {
                    continue;
                }
                let n = a as usize * nx + b as usize;
                if free[n] && lab[n] == 0 {
                    lab[n] = k;
                    stack.push(n);
                }
            }
        }
    }
    (lab, k as usize)
}

fn label_strips(
    free: &[bool],
    ny: usize,
    nx: usize,
    conn: Connectivity,
    per: Periodic,
    strip_rows: usize,
) -> (Vec<u32>, usize) {
    // Stale content in the buffer must not matter.
    let mut labels = vec![7u32; ny * nx];
    let sums = run(
        &FreeMask(free),
        None,
        setup(ny, nx, conn, per),
        strip_rows,
        &mut labels,
    )
    .unwrap();
    (labels, sums.n_clusters)
}

fn parse(rows: &[&str]) -> (Vec<bool>, usize, usize) {
    let ny = rows.len();
    let nx = rows[0].len();
    let free = rows
        .iter()
        .flat_map(|r| r.chars().map(|c| c == '.'))
        .collect();
    (free, ny, nx)
}

fn classify_rows(rows: &[&str], conn: Connectivity, per: Periodic, flow: Flow) -> Vec<u8> {
    let (free, ny, nx) = parse(rows);
    let gap = vec![1.0; ny * nx];
    let (_, c) = analyze(&FreeMask(&free), &gap, ny, nx, 1.0, conn, per).unwrap();
    classify(&c, flow).unwrap().classes
}

#[test]
fn open_cells_are_free_cells_with_a_positive_gap() {
    let (ny, nx) = (37, 131);
    let contact = random_mask(ny, nx, 0.3, 5);
    let mut rng = Rng(77);
    // Positive, zero, negative and NaN gaps.
    let gap: Vec<f64> = (0..ny * nx)
        .map(|k| match k % 7 {
            0 => 0.0,
            1 => -1e-12,
            2 => f64::NAN,
            _ => rng.unit() + 1e-300,
        })
        .collect();
    for contact in [Some(&contact[..]), None] {
        let open = OpenCells { gap: &gap, contact };
        let want: Vec<bool> = (0..ny * nx)
            .map(|k| is_open(gap[k], contact.is_some_and(|c| c[k])))
            .collect();
        assert!(want.iter().any(|&o| o) && want.iter().any(|&o| !o));
        for start in (0..ny * nx).step_by(64) {
            let len = (ny * nx - start).min(64);
            let bits = open.pack(start, len);
            for k in 0..len {
                assert_eq!(bits >> k & 1 == 1, want[start + k], "cell {}", start + k);
            }
        }
        let per = Periodic::default();
        let mut a = vec![0u32; ny * nx];
        let na = label_into(&open, ny, nx, Connectivity::Four, per, &mut a).unwrap();
        let (b, nb) = label(&want, ny, nx, Connectivity::Four, per).unwrap();
        assert_eq!((a, na), (b, nb));
    }
}

#[test]
fn clusters_pack_bools_matches_bytewise() {
    for seed in 0..50 {
        let m = random_mask(1, 64, 0.5, seed);
        for len in [1, 7, 8, 9, 63, 64] {
            let want = m[..len]
                .iter()
                .enumerate()
                .fold(0u64, |b, (k, &x)| b | (x as u64) << k);
            assert_eq!(pack_bools(&m[..len]), want);
        }
    }
}

#[test]
fn clusters_hand_made_shapes() {
    let four = Connectivity::Four;
    let none = Periodic::default();
    // Straight channel along axis 0 spans; the pocket is trapped.
    let c = classify_rows(
        &["#.###", "#.#.#", "#.###", "#.###"],
        four,
        none,
        Flow::Axis0,
    );
    assert_eq!(c, vec![SPANNING, TRAPPED]);
    // Blocked channel: two dead ends.
    let c = classify_rows(&["#.#", "#.#", "###", "#.#"], four, none, Flow::Axis0);
    assert_eq!(c, vec![DEAD_END, DEAD_END]);
    // Touches one side only.
    let c = classify_rows(&["###", "..#", "###"], four, none, Flow::Axis0);
    assert_eq!(c, vec![DEAD_END]);
    // Diagonal connection: one cluster with 8, two with 4.
    let (free, ny, nx) = parse(&[".#", "#."]);
    assert_eq!(label(&free, ny, nx, four, none).unwrap().1, 2);
    assert_eq!(
        label(&free, ny, nx, Connectivity::Eight, none).unwrap(),
        (vec![1, 0, 0, 1], 1)
    );
}

#[test]
fn clusters_periodic_wrap_changes_class() {
    let four = Connectivity::Four;
    // A channel that leaves at the right edge and re-enters at the left one.
    let rows = ["###.#", ".##..", ".####", ".####"];
    let (free, ny, nx) = parse(&rows);
    let wrap1 = Periodic {
        axis0: false,
        axis1: true,
    };
    assert_eq!(
        label(&free, ny, nx, four, Periodic::default()).unwrap().1,
        2
    );
    assert_eq!(
        classify_rows(&rows, four, Periodic::default(), Flow::Axis0),
        vec![DEAD_END, DEAD_END]
    );
    assert_eq!(label(&free, ny, nx, four, wrap1).unwrap().1, 1);
    assert_eq!(
        classify_rows(&rows, four, wrap1, Flow::Axis0),
        vec![SPANNING]
    );
    // Touching the wrapped edges only is not touching a boundary.
    let pocket = ["#####", "..#..", "#####"];
    assert_eq!(
        classify_rows(&pocket, four, wrap1, Flow::Axis0),
        vec![TRAPPED]
    );
    assert_eq!(
        classify_rows(&pocket, four, Periodic::default(), Flow::Axis0),
        vec![DEAD_END, DEAD_END]
    );
}

#[test]
fn clusters_either_and_both() {
    let four = Connectivity::Four;
    let none = Periodic::default();
    let cross = ["#.#", "...", "#.#"];
    let line = ["###", "...", "###"];
    assert_eq!(
        classify_rows(&cross, four, none, Flow::Both),
        vec![SPANNING]
    );
    assert_eq!(classify_rows(&line, four, none, Flow::Both), vec![DEAD_END]);
    assert_eq!(
        classify_rows(&line, four, none, Flow::Either),
        vec![SPANNING]
    );
    assert_eq!(
        classify_rows(&line, four, none, Flow::Axis0),
        vec![DEAD_END]
    );
}

#[test]
fn clusters_bad_arguments_are_errors() {
    let m = vec![true; 6];
    let none = Periodic::default();
    let four = Connectivity::Four;
    let e = label(&m, 2, 4, four, none).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "mask", .. }));
    let e = Connectivity::from_neighbours(6).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidArgument {
            name: "connectivity",
            ..
        }
    ));
    let e = Flow::parse("2").unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "flow", .. }));
    let mut g = vec![1.0; 6];
    let e = analyze(&FreeMask(&m), &g, 2, 3, 0.0, four, none).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "dx", .. }));
    let e = analyze(&FreeMask(&m), &g[..5], 2, 3, 1.0, four, none).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "gap", .. }));
    g[4] = f64::NAN;
    let e = analyze(&FreeMask(&m), &g, 2, 3, 1.0, four, none).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "gap", .. }));
    let wrap0 = Periodic {
        axis0: true,
        axis1: false,
    };
    let (_, c) = analyze(&FreeMask(&m), &[1.0; 6], 2, 3, 1.0, four, wrap0).unwrap();
    let e = classify(&c, Flow::Axis0).unwrap_err();
    assert!(matches!(
        e,
        Error::InvalidArgument {
            name: "periodic_axis0",
            ..
        }
    ));
    assert!(classify(&c, Flow::Axis1).is_ok());
    assert!(classify(&c, Flow::Either).is_err());
}

#[test]
fn clusters_empty_and_degenerate_grids() {
    let four = Connectivity::Four;
    let none = Periodic::default();
    assert_eq!(label(&[], 0, 5, four, none).unwrap(), (vec![], 0));
    assert_eq!(label(&[true], 1, 1, four, none).unwrap(), (vec![1], 1));
    let all = Periodic {
        axis0: true,
        axis1: true,
    };
    assert_eq!(
        label(&[true], 1, 1, Connectivity::Eight, all).unwrap(),
        (vec![1], 1)
    );
    // One row, one column: the cluster touches both ends along its length.
    assert_eq!(
        classify_rows(&["..."], four, none, Flow::Axis0),
        vec![SPANNING]
    );
}

#[test]
fn clusters_same_result_on_one_and_two_threads() {
    let (ny, nx) = (517, 389);
    let free = random_mask(ny, nx, 0.6, 7);
    let mut rng = Rng(99);
    let gap: Vec<f64> = (0..ny * nx).map(|_| rng.unit()).collect();
    let per = Periodic {
        axis0: false,
        axis1: true,
    };
    let go = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut labels = vec![0u32; ny * nx];
            let s = setup(ny, nx, Connectivity::Four, per);
            let c = analyze_strips(&FreeMask(&free), &gap, s, 0.5, 16, &mut labels).unwrap();
            (labels, c)
        })
    };
    let (a, b) = (go(1), go(2));
    assert_eq!(a, b);
    let bits = |c: &Clusters| c.volumes.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a.1), bits(&b.1));
    assert_eq!(a.0, bfs_labels(&free, ny, nx, Connectivity::Four, per).0);
}

#[test]
fn clusters_sources_agree() {
    let (ny, nx) = (33, 150);
    let mut rng = Rng(5);
    let gap: Vec<f64> = (0..ny * nx).map(|_| rng.unit() - 0.4).collect();
    let free: Vec<bool> = gap.iter().map(|&g| g > 0.0).collect();
    let contact: Vec<bool> = free.iter().map(|&f| !f).collect();
    let c4 = Connectivity::Four;
    let none = Periodic::default();
    let go = |src: &dyn Fn(&mut [u32]) -> Result<usize>| {
        let mut labels = vec![0u32; ny * nx];
        let n = src(&mut labels).unwrap();
        (labels, n)
    };
    let a = go(&|l| label_into(&FreeMask(&free), ny, nx, c4, none, l));
    let b = go(&|l| label_into(&ContactMask(&contact), ny, nx, c4, none, l));
    let c = go(&|l| label_into(&PositiveGap(&gap), ny, nx, c4, none, l));
    assert_eq!(a, b);
    assert_eq!(a, c);
}

fn arb_case() -> impl Strategy<Value = (usize, usize, f64, u64, bool, bool, bool, usize)> {
    (
        1usize..48,
        1usize..140,
        0.2f64..0.9,
        any::<u64>(),
        any::<bool>(),
        any::<bool>(),
        any::<bool>(),
        1usize..12,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// Labels equal a breadth-first search numbered in raster order, for any strip height.
    #[test]
    fn clusters_match_bfs((ny, nx, p, seed, eight, w0, w1, strip) in arb_case()) {
        let free = random_mask(ny, nx, p, seed);
        let conn = if eight { Connectivity::Eight } else { Connectivity::Four };
        let per = Periodic { axis0: w0, axis1: w1 };
        let want = bfs_labels(&free, ny, nx, conn, per);
        prop_assert_eq!(label_strips(&free, ny, nx, conn, per, strip), want.clone());
        prop_assert_eq!(label(&free, ny, nx, conn, per).unwrap(), want);
    }

    /// Per-cluster sums equal direct sums over the labels; class volumes add up to the
    /// free volume.
    #[test]
    fn clusters_sums_and_classes((ny, nx, p, seed, eight, w0, w1, strip) in arb_case()) {
        let free = random_mask(ny, nx, p, seed);
        let mut rng = Rng(seed | 1);
        let gap: Vec<f64> = (0..ny * nx).map(|_| rng.unit() * 10.0).collect();
        let conn = if eight { Connectivity::Eight } else { Connectivity::Four };
        // Wrap across the flow axis only (axis 0 when w0, else axis 1).
        let (per, flow) = match (w0, w1) {
            (true, _) => (Periodic { axis0: true, axis1: false }, Flow::Axis1),
            (false, true) => (Periodic { axis0: false, axis1: true }, Flow::Axis0),
            (false, false) => (Periodic::default(), if eight { Flow::Either } else { Flow::Both }),
        };
        let dx = 0.3;
        let mut labels = vec![0u32; ny * nx];
        let s = setup(ny, nx, conn, per);
        let c = analyze_strips(&FreeMask(&free), &gap, s, dx, strip, &mut labels).unwrap();
        let k = c.n_clusters;
        let mut area = vec![0u64; k];
        let mut vol = vec![0.0f64; k];
        let mut touch = vec![0u8; k];
        for i in 0..ny {
            for j in 0..nx {
                let l = labels[i * nx + j] as usize;
                if l == 0 { continue; }
                area[l - 1] += 1;
                vol[l - 1] += gap[i * nx + j] * dx * dx;
                touch[l - 1] |= if i == 0 { TOUCH_FIRST_ROW } else { 0 }
                    | if i + 1 == ny { TOUCH_LAST_ROW } else { 0 }
                    | if j == 0 { TOUCH_FIRST_COL } else { 0 }
                    | if j + 1 == nx { TOUCH_LAST_COL } else { 0 };
            }
        }
        prop_assert_eq!(&c.areas, &area);
        prop_assert_eq!(&c.touches, &touch);
        for (a, b) in c.volumes.iter().zip(&vol) {
            prop_assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0));
        }
        let cl = classify(&c, flow).unwrap();
        let parts = cl.spanning_volume + cl.dead_end_volume + cl.trapped_volume;
        prop_assert!((parts - cl.free_volume).abs() <= 1e-12 * cl.free_volume.max(1e-300));
        let direct: f64 = free.iter().zip(&gap).filter(|(f, _)| **f).map(|(_, g)| g * dx * dx).sum();
        prop_assert!((cl.free_volume - direct).abs() <= 1e-12 * direct.max(1.0));
        prop_assert_eq!(cl.free_area, free.iter().filter(|f| **f).count() as u64);
        prop_assert_eq!(cl.n_spanning + cl.n_dead_end + cl.n_trapped, k);
    }
}
