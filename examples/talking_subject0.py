# Writes examples/talking_subject0.csv: subject 0 of the talking-video cohort in a run's
# reference.csv, in OpenFace 2.0's layout (", " separators, no face_id), 30 fps.
# python3 examples/talking_subject0.py results/paper/latest/reference.csv examples/talking_subject0.csv
import csv,sys
src,dst=sys.argv[1],sys.argv[2]
aus=['AU01','AU02','AU04','AU05','AU06','AU07','AU09','AU10','AU12','AU14','AU15','AU17','AU20','AU23','AU25','AU26','AU45']
r=[x for x in csv.DictReader(open(src)) if x['cohort']=='talking_videos' and x['subject']=='0']
out=['frame, timestamp, confidence, success, '+', '.join(a+'_r' for a in aus)]
for i,x in enumerate(r):
    out.append(f"{i+1}, {i/30:.3f}, 0.98, 1, "+', '.join(f"{float(x[a]):.2f}" for a in aus))
open(dst,'w').write('\n'.join(out)+'\n')
