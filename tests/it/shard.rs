//! Suites larger than one machine: `--shard K/N` splits the scenes the
//! same way everywhere, and `rendiff report` merges the shards' verdicts.

use std::collections::BTreeSet;
use std::process::Command;

use crate::util::root;

fn rendiff(args: &[&str]) -> (i32, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(root())
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr),
    )
}

fn scenes_of(json: &str) -> Vec<String> {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    let items = match v {
        serde_json::Value::Array(items) => items,
        one => vec![one],
    };
    items
        .iter()
        .map(|r| r["scene"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn shards_partition_the_suite_and_merge_into_one_report() {
    let all: Vec<String> = crate::util::bundled_scenes()
        .iter()
        .map(|s| format!("scenes/{s}.toml"))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let mut seen = BTreeSet::new();
    let mut files = Vec::new();
    for k in 1..=3 {
        let shard = format!("{k}/3");
        let mut args = vec!["diff", "--size", "16x12", "--json", "--shard", &shard];
        args.extend(all.iter().map(String::as_str));
        let (code, json) = rendiff(&args);
        assert_eq!(code, 0, "{json}");
        // The same shard from a reversed list: the assignment is by path.
        let mut rev = vec!["diff", "--size", "16x12", "--json", "--shard", &shard];
        rev.extend(all.iter().rev().map(String::as_str));
        let (_, json_rev) = rendiff(&rev);
        let mut a = scenes_of(&json);
        let mut b = scenes_of(&json_rev);
        a.sort();
        b.sort();
        assert_eq!(a, b, "shard {shard} depends on the order");
        for s in a {
            assert!(seen.insert(s.clone()), "{s} is in two shards");
        }
        let f = dir.path().join(format!("s{k}.json"));
        std::fs::write(&f, json).unwrap();
        files.push(f);
    }
    assert_eq!(
        seen,
        all.iter().cloned().collect::<BTreeSet<_>>(),
        "every scene in one shard"
    );
    let paths: Vec<&str> = files.iter().map(|f| f.to_str().unwrap()).collect();
    let mut args = vec!["report"];
    args.extend(&paths);
    let (code, text) = rendiff(&args);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains(&format!(
            "{} report(s): {} passed, 0 failed",
            all.len(),
            all.len()
        )),
        "{text}"
    );
    // A failed scene in any shard fails the merged report.
    let failing = dir.path().join("fail.json");
    std::fs::write(
        &failing,
        r#"{"scene": "x.toml", "a": "raster", "b": "ray", "verdict": "fail"}"#,
    )
    .unwrap();
    args.push(failing.to_str().unwrap());
    let (code, text) = rendiff(&args);
    assert_eq!(code, 1, "{text}");
    // Not a report: exit 2, naming the file.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"hello\": 1}").unwrap();
    let (code, text) = rendiff(&["report", bad.to_str().unwrap()]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("bad.json"), "{text}");
    // A malformed shard is a usage error.
    let (code, _) = rendiff(&["diff", "scenes/spheres.toml", "--shard", "4/3"]);
    assert_eq!(code, 2);
}
