# Maintainer's tool: draws the demo leaf's page image (tests/data/demo_page.png): a parchment
# leaf of 56 x 70 mm at 20 px/mm with ruled lines of script text, a red initial and a folio
# number: asymmetric, so a mirrored or turned result shows at once.
import cv2, numpy as np, sys
w, h = 1120, 1400
rng = np.random.default_rng(7)
page = np.zeros((h, w, 3), np.float32)
page[:] = (150, 196, 222)  # parchment, BGR
# Uneven parchment: a low-frequency mottle.
m = cv2.resize(rng.normal(0, 1, (14, 11)).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
page += (m * 6)[..., None]
ink = (40, 45, 60)
words = ("In principio erat verbum et verbum erat apud deum et deus erat verbum hoc erat in "
         "principio apud deum omnia per ipsum facta sunt et sine ipso factum est nihil quod "
         "factum est in ipso vita erat et vita erat lux hominum et lux in tenebris lucet et "
         "tenebrae eam non conprehenderunt fuit homo missus a deo cui nomen erat iohannes").split()
left, right, top, step = 150, 1010, 190, 70
y, k = top, 0
cv2.putText(page, "7", (1000, 110), cv2.FONT_HERSHEY_SCRIPT_COMPLEX, 1.6, ink, 2, cv2.LINE_AA)
while y < h - 150:
    cv2.line(page, (left - 20, y + 8), (right + 10, y + 8), (120, 160, 190), 1, cv2.LINE_AA)
    x = left + (140 if y < top + 3 * step else 0)
    while k < len(words) * 4:
        word = words[k % len(words)]
        (tw, _), _ = cv2.getTextSize(word, cv2.FONT_HERSHEY_SCRIPT_COMPLEX, 1.55, 3)
        if x + tw > right: break
        cv2.putText(page, word, (x, y), cv2.FONT_HERSHEY_SCRIPT_COMPLEX, 1.55, ink, 3, cv2.LINE_AA)
        x += tw + 24; k += 1
    y += step
# The red initial, three lines tall.
cv2.putText(page, "I", (left - 10, top + 2 * step), cv2.FONT_HERSHEY_TRIPLEX, 6.2, (40, 40, 175), 12, cv2.LINE_AA)
cv2.imwrite(sys.argv[1], np.clip(page, 0, 255).astype(np.uint8), [cv2.IMWRITE_PNG_COMPRESSION, 9])
