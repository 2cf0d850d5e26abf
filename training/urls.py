from django.urls import path

from training import views

app_name = "training"
urlpatterns = [
    path("models/", views.model_list, name="model-list"),
    path("models/create/", views.model_create, name="model-create"),
    path("models/name-check/", views.model_name_check, name="model-name-check"),
    path("models/<int:pk>/", views.model_detail, name="model-detail"),
    path("models/<int:pk>/stop/", views.model_stop, name="model-stop"),
    path("models/<int:pk>/log.txt", views.model_log, name="model-log"),
    path("models/<int:pk>/log/", views.model_log_panel, name="model-log-panel"),
    path("models/<int:pk>/files/<path:relative>", views.model_file, name="model-file"),
    path("models/<int:pk>/delete/", views.model_delete, name="model-delete"),
    path("models/<int:pk>/evaluate/", views.evaluation_create, name="evaluation-create"),
    path(
        "models/<int:pk>/evaluations/<int:evaluation>/",
        views.evaluation_detail,
        name="evaluation-detail",
    ),
    path(
        "models/<int:pk>/evaluations/<int:evaluation>/stop/",
        views.evaluation_stop,
        name="evaluation-stop",
    ),
    path(
        "models/<int:pk>/evaluations/<int:evaluation>/files/<path:name>",
        views.evaluation_file,
        name="evaluation-file",
    ),
    path("garage/", views.garage, name="garage"),
    path("garage/<int:pk>/edit/", views.vehicle_edit, name="vehicle-edit"),
    path("garage/<int:pk>/delete/", views.vehicle_delete, name="vehicle-delete"),
    path("models/reward-function/", views.reward_editor, name="reward-editor"),
    path("models/reward-function/<int:pk>/", views.reward_editor, name="reward-function"),
    path(
        "models/reward-function/<int:pk>/delete/",
        views.reward_function_delete,
        name="reward-function-delete",
    ),
    path("models/reward-function/validate/", views.reward_validation, name="reward-validation"),
    path("tracks/<slug:name>/", views.track_detail, name="track-detail"),
    path("tracks/<slug:name>.png", views.track_preview, name="track-preview"),
]
