//! The split's tests: ranks, grouped assignment, published splits and their files.

use super::*;

fn photos(n: usize) -> Vec<(u32, String)> {
    (0..n)
        .map(|i| (i as u32 + 1, format!("p{i:05}.jpg")))
        .collect()
}

#[test]
fn groups_go_whole_to_one_side_and_late_members_follow_them() {
    let all = photos(60);
    // Ten groups of three (p00000–p00029), the rest alone.
    let groups: BTreeMap<String, u32> = all[..30]
        .iter()
        .map(|(id, n)| (n.clone(), (id - 1) / 3))
        .collect();
    for seed in 0..200 {
        let (a, c) = assign_grouped(&all, &[], 10, seed, &groups).unwrap();
        assert!(straddling(&a, &groups).is_empty(), "seed {seed}");
        assert_eq!(
            c.new_val, 10,
            "seed {seed}: singles fill what groups cannot"
        );
    }
    // A photo that joins a group later goes where the group already is.
    let (first, _) = assign_grouped(&all[..59], &[], 10, 3, &groups).unwrap();
    let mut later = groups.clone();
    later.insert(all[59].1.clone(), 0);
    let side0 = first
        .iter()
        .find(|a| a.name == all[0].1)
        .unwrap()
        .split
        .clone();
    let (second, c) = assign_grouped(&all, &first, 10, 3, &later).unwrap();
    let joined = second.iter().find(|a| a.name == all[59].1).unwrap();
    assert_eq!((joined.split.clone(), c.new_train + c.new_val), (side0, 1));
    // A published split that parts a group is reported, naming its members.
    let mut parted = first.clone();
    for a in parted
        .iter_mut()
        .filter(|a| groups.get(&a.name) == Some(&1))
        .take(1)
    {
        a.split = if a.split == VAL { TRAIN } else { VAL }.into();
    }
    let s = straddling(&parted, &groups);
    assert_eq!(s.len(), 1);
    assert_eq!(
        s[0].1,
        vec![all[3].1.clone(), all[4].1.clone(), all[5].1.clone()]
    );
}

#[test]
fn exact_counts_disjoint_and_deterministic() {
    let (a, c) = assign(&photos(1000), &[], 100, 7).unwrap();
    assert_eq!(a.iter().filter(|x| x.split == "val").count(), 100);
    assert_eq!((c.new_val, c.new_train), (100, 900));
    let mut names: Vec<&str> = a.iter().map(|x| x.name.as_str()).collect();
    names.dedup();
    assert_eq!(
        names.len(),
        1000,
        "each photo once: train and val are disjoint"
    );
    assert_eq!(
        assign(&photos(1000), &[], 100, 7).unwrap().0,
        a,
        "same seed, same split"
    );
    assert_ne!(
        assign(&photos(1000), &[], 100, 8).unwrap().0,
        a,
        "another seed, another split"
    );
    // Order of the input does not matter.
    let mut rev = photos(1000);
    rev.reverse();
    assert_eq!(assign(&rev, &[], 100, 7).unwrap().0, a);
}

#[test]
fn new_photos_never_move_old_assignments() {
    let (first, _) = assign(&photos(500), &[], 50, 1).unwrap();
    let (second, c) = assign(&photos(800), &first, 80, 99).unwrap();
    for a in &first {
        assert!(second.contains(a), "{a:?} changed");
    }
    assert_eq!((c.kept_val, c.new_val, c.new_train), (50, 30, 270));
    assert_eq!(second.iter().filter(|x| x.split == "val").count(), 80);
}

#[test]
fn impossible_requests_name_both_numbers() {
    let e = assign(&photos(19), &[], 100, 1).unwrap_err();
    assert!(
        e.contains("`split.val` 100") && e.contains("only 19"),
        "{e}"
    );
    let (first, _) = assign(&photos(50), &[], 10, 1).unwrap();
    let e = assign(&photos(50), &first, 5, 1).unwrap_err();
    assert!(
        e.contains("`split.val` 5") && e.contains("10 validation photos already"),
        "{e}"
    );
    let (none, c) = assign(&photos(5), &[], 0, 1).unwrap();
    assert_eq!((none.len(), c.new_val), (5, 0));
    let (tiny, _) = assign(&photos(1), &[], 1, 1).unwrap();
    assert_eq!(tiny[0].split, "val");
}

#[test]
fn a_phototourism_tsv_assigns_exactly_its_sets() {
    let p = std::path::Path::new("brandenburg.tsv");
    let text = "filename\tid\tsplit\tdataset\n\
                a.jpg\t1\ttrain\tb\n\
                b.jpg\t\ttrain\tb\n\
                c.jpg\tnan\ttest\tb\n\
                d.png\t4\ttest\tb\n\
                e.jpg\t5\ttrain\tb\n";
    let rows = parse_phototourism_tsv(p, text).unwrap();
    assert_eq!(
        rows.len(),
        3,
        "rows without id are dropped, as nerf_pl does"
    );
    let model: Vec<(u32, String)> = ["a.jpg", "b.jpg", "c.jpg", "d.jpg", "e.jpg", "f.jpg"]
        .iter()
        .enumerate()
        .map(|(i, n)| (i as u32 + 10, n.to_string()))
        .collect();
    let kept = [10, 11, 12, 13, 15].into_iter().collect();
    let a = assign_from_tsv(p, &rows, &model, &kept).unwrap();
    let got: Vec<(&str, &str)> = a
        .rows
        .iter()
        .map(|r| (r.name.as_str(), r.split.as_str()))
        .collect();
    // d.png is d.jpg re-encoded; e.jpg is listed but dropped by ingest.
    assert_eq!(got, [("a.jpg", "train"), ("d.jpg", "val")]);
    assert_eq!(a.not_kept, ["e.jpg"]);
    assert_eq!(a.unlisted, 3);
    let unknown = parse_phototourism_tsv(p, "filename\tid\tsplit\nzz.jpg\t3\ttrain\n").unwrap();
    let e = assign_from_tsv(p, &unknown, &model, &kept)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("\"zz.jpg\" (line 2)") && e.contains("match no image"),
        "{e}"
    );
    let e = parse_phototourism_tsv(p, "filename\tid\tsplit\na.jpg\t1\tval\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 2") && e.contains("`split`"), "{e}");
    let e = parse_phototourism_tsv(p, "name\tid\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no `filename` column"), "{e}");
    let twice = parse_phototourism_tsv(p, "filename\tid\tsplit\na.jpg\t1\ttrain\na.jpg\t1\ttest\n")
        .unwrap();
    let e = assign_from_tsv(p, &twice, &model, &kept)
        .unwrap_err()
        .to_string();
    assert!(e.contains("listed again (first on line 2)"), "{e}");
}
