"""Summarises scripts/refcheck.sh output: head/base ratios of steps_per_s per case (medians)."""
import json, glob, sys, statistics, math, os
d = sys.argv[1]
def load(pattern):
    out = {}
    for f in sorted(glob.glob(os.path.join(d, pattern))):
        for line in open(f):
            line = line.strip()
            if not line.startswith('{'): continue
            r = json.loads(line)
            if 'case' not in r: continue
            key = (r['case'], r.get('envs'), r.get('threads'))
            out.setdefault(key, []).append(r['steps_per_s'])
    return out
for suite in ['tasks', 'fem', 'pbd']:
    h = load(f'{suite}_head_*.json'); b = load(f'{suite}_base_*.json')
    ratios = []
    print(f'== {suite}')
    for k in sorted(h):
        if k not in b: print('  only head', k); continue
        mh, mb = statistics.median(h[k]), statistics.median(b[k])
        r = mh / mb; ratios.append(r)
        print(f'  {k[0]:<34} envs {k[1]} thr {k[2]}: head {mh:10.1f} {[round(x) for x in h[k]]} base {mb:10.1f} {[round(x) for x in b[k]]} ratio {r:.3f}')
    if ratios:
        g = math.exp(sum(map(math.log, ratios)) / len(ratios))
        print(f'  {len(ratios)} cases: geometric mean {g:.3f}, min {min(ratios):.3f}, max {max(ratios):.3f}')
